"""Calibration on the shipped real laser-tracker data: stiff against the numpy/scipy reference
(bench/peers/absolute_ref.py) in the same run, and docs/real-data.md regenerated from it.

    .venv/bin/python bench/real_data.py                 # both datasets, writes docs/real-data.md
    .venv/bin/python bench/real_data.py --only ur5      # one dataset (the doc keeps the other)
    .venv/bin/python bench/real_data.py --no-product    # the reference alone
    .venv/bin/python bench/real_data.py --only pooled   # speed on the four UR10 series pooled
    .venv/bin/python bench/real_data.py --only loop     # the stiff diagnose --auto loops

stiff is run through its command line, as a user would: `stiff identify --robot R --data F
--model registration+tool+joint_offset+kinematic[+gravity_lumped] -o fit.json`, then
`stiff predict --fit fit.json --data V -o pred.csv`. When the installed stiff cannot calibrate
absolute data, its part is skipped with the reason and the reference's results stand alone.
Results (with the per-pose errors) go to bench/results/real_data.json; plots to
docs/real-data/*.png.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import re
import time
from pathlib import Path

# One thread for the reference's linear algebra, as stiff's solver runs (Ceres, one thread):
# the ratios compare the methods, not the number of cores; threaded BLAS on a shared machine
# also makes the reference's times erratic. Set before numpy loads its BLAS.
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE / "peers"))
import absolute_ref as ref  # noqa: E402

REAL = ROOT / "examples" / "real"
RESULTS = HERE / "results" / "real_data.json"
DOC = ROOT / "docs" / "real-data.md"
FIGS = ROOT / "docs" / "real-data"

GEOMETRY = "registration+tool+joint_offset+kinematic"
MODELS = {"geometry": GEOMETRY, "geometry+gravity": GEOMETRY + "+gravity_lumped",
          "geometry+harmonics": GEOMETRY + "+harmonic",
          "geometry+gravity+harmonics": GEOMETRY + "+gravity_lumped+harmonic"}


def ur10_model(name):
    """The UR10's T-Mac gives the probe's orientation: the full tool frame (tool +
    tool_orientation), and the orientation residuals enter the fit."""
    return MODELS[name].replace("+tool+", "+tool+tool_orientation+", 1)


# ----------------------------------------------------------------------------- product

def stiff_exe():
    if os.environ.get("STIFF_EXE"):
        return os.environ["STIFF_EXE"]
    exe = shutil.which("stiff")
    venv = ROOT / ".venv" / "bin" / "stiff"
    return str(venv) if venv.exists() else exe


class ProductUnavailable(Exception):
    pass


def _run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise ProductUnavailable(f"`{' '.join(cmd[1:4])} ...` failed: "
                                 f"{(r.stderr or r.stdout).strip().splitlines()[-1:]}")
    return r.stdout


def write_rows(src, idx, dst):
    """A copy of an absolute CSV with only the data rows idx (metadata and header kept)."""
    lines = Path(src).read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")][0]
    body = lines[head + 1:]
    Path(dst).write_text("\n".join(lines[:head + 1] + [body[i] for i in idx]) + "\n")


def library_seconds(robot, train, model):
    """The identification alone, in this process through the Python package (as the
    reference's least_squares is timed): best of three; None without the package."""
    try:
        import stiff
    except ImportError:
        return None
    r = stiff.Robot(robot)
    d = stiff.Dataset.read(str(train), r)
    best = math.inf
    for _ in range(3):  # CPU seconds, as the reference's: one thread each
        t = time.process_time()
        stiff.identify(r, d, model=model)
        best = min(best, time.process_time() - t)
    return best


def predicted_errors(robot, fit, test, pred, degrees=False):
    """`stiff predict` of the absolute file `test` with `fit` (into `pred`): the per-pose
    distances [mm] between the predicted and the measured positions; with `degrees`, also the
    per-pose angles [deg] between the predicted and the measured orientations."""
    _run([stiff_exe(), "predict", "--robot", robot, "--fit", fit, "--data", str(test),
          "-o", pred])
    with open(pred) as f:
        rows = list(csv.DictReader(f))
    P = {r["id"]: np.array([float(r["x_m"]), float(r["y_m"]), float(r["z_m"])]) for r in rows}
    d = ref.read_absolute(test)
    e = np.array([np.linalg.norm(P[i] - p) for i, p in zip(d["ids"], d["p"])]) * 1e3
    if not degrees:
        return e
    from scipy.spatial.transform import Rotation
    W = {r["id"]: [float(r[k]) for k in ("rx_rad", "ry_rad", "rz_rad")] for r in rows}
    Rp = Rotation.from_rotvec([W[i] for i in d["ids"]]).as_matrix()
    return e, np.degrees(np.linalg.norm(ref.rotation_error(d["R"], Rp), axis=1))


def product_errors(robot, train, test, model, tmp, degrees=False):
    """Calibrate with stiff on `train`, predict `test`: per-pose position errors [mm] (with
    `degrees`, and orientation errors [deg]), the number of identified parameters,
    calibration RMS [mm] (and [deg] per axis) and the identify time [s]."""
    exe = stiff_exe()
    fit = os.path.join(tmp, "fit.json")
    pred = os.path.join(tmp, "pred.csv")
    t = time.perf_counter()
    _run([exe, "identify", "--robot", robot, "--data", str(train), "--model", model,
          "-o", fit])
    seconds = time.perf_counter() - t
    library = library_seconds(robot, train, model)
    e = predicted_errors(robot, fit, test, pred, degrees)
    fitstats = json.loads(Path(fit).read_text()).get("fit", {})
    st = {"parameters": fitstats.get("rank"),
          "rms_mm": (fitstats.get("rms_m") or float("nan")) * 1e3 * math.sqrt(3),
          "seconds": seconds, "library_seconds": library}
    if fitstats.get("oriented_rows"):
        st["rms_deg"] = math.degrees(fitstats["orientation_rms_rad"]) * math.sqrt(3)
    return e, st


def pooled_ur10(path):
    """The four UR10 series in one file (positions only, four sessions): the columns they
    share. Returns the row count."""
    cols = ["id", "session"] + [f"q{j}_rad" for j in range(1, 7)] + ["px_mm", "py_mm", "pz_mm"]
    out = ["# robot: ur10", "# frame: laser tracker (one placement per series)", ",".join(cols)]
    for k in "ABCD":
        lines = (REAL / "ur10" / ref.UR10_SERIES[k]).read_text().splitlines()
        for r in csv.DictReader(ln for ln in lines if not ln.startswith("#")):
            out.append(",".join(r[c] for c in cols))
    Path(path).write_text("\n".join(out) + "\n")
    return len(out) - 3


def speed_pooled():
    """Identification time at about 10^4 rows: the UR10 series pooled, geometry and
    geometry+gravity, the reference's least_squares against the library in the same run."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        f = os.path.join(tmp, "ur10_pooled.csv")
        rows = pooled_ur10(f)
        d = ref.read_absolute(f)
        dh = ref.robot_dh("ur10")
        for n in ("geometry", "geometry+gravity"):
            cal = ref.calibrate(dh, d, gravity=n.endswith("gravity"))
            out[n] = {"rows": rows, "reference": cal.stats,
                      "library_seconds": library_seconds("ur10", f, MODELS[n])}
            try:
                import stiff
                r = stiff.Robot("ur10")
                fit = stiff.identify(r, stiff.Dataset.read(f, r), model=MODELS[n])
                out[n]["stiff_parameters"] = fit.statistics.rank
            except ImportError:
                pass
            print(f"pooled {n}: {rows} rows, least_squares "
                  f"{cal.stats['least_squares_seconds']:.2f} s, library "
                  f"{out[n]['library_seconds'] or float('nan'):.2f} s")
    return out


def diagnose_loop(robot, calib, valid, tmp, repeatability_mm=None):
    """`stiff diagnose --auto` from the nominal model (registration and tool): its steps."""
    out = os.path.join(tmp, "diagnosis.json")
    t = time.perf_counter()
    _run([stiff_exe(), "diagnose", "--robot", robot, "--data", str(calib), "--validate",
          str(valid), "--model", "registration+tool", "--auto", "--max-steps", "4",
          "--json", out]
         + (["--repeatability", str(repeatability_mm)] if repeatability_mm else []))
    seconds = time.perf_counter() - t
    d = json.loads(Path(out).read_text())
    steps = []
    for st in d["steps"]:
        e = np.asarray(st["validation_error_m"]) * 1e3
        steps.append({"model": st["model"], "added": st["added"], "verdict": st["verdict"],
                      "parameters": st["parameters"],
                      "fit_rms_mm": st["rms_m"] * 1e3 * math.sqrt(3),
                      "validation": summary(e)})
        cv = [x for x in st.get("cross_validation_error_m") or [] if x is not None]
        if cv:
            steps[-1]["cross_validated"] = summary(np.asarray(cv) * 1e3)
    return {"steps": steps, "final_model": d["final_model"],
            "final_verdict": d["final_verdict"], "seconds": seconds,
            "repeatability_mm": repeatability_mm, "notes": d.get("notes", [])}


def loops():
    """The loop on UR5 (grid -> the 20 random poses) and on UR10 (series C -> series B, a
    set-up of its own that the diagnosis registers from a fifth of its rows)."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        # The UR5's data sheet states a pose repeatability of +-0.1 mm (ISO 9283).
        out["ur5"] = diagnose_loop("ur5", REAL / "ur5" / "ur5_grid.csv",
                                   REAL / "ur5" / "ur5_random.csv", tmp, repeatability_mm=0.1)
        out["ur10"] = diagnose_loop("ur10", REAL / "ur10" / ref.UR10_SERIES["C"],
                                    REAL / "ur10" / ref.UR10_SERIES["B"], tmp)
    for k, v in out.items():
        print(f"loop {k}: " + " -> ".join(f"{st['model']} {st['validation']['mean_mm']:.4f}"
                                          for st in v["steps"]) + f" ({v['final_verdict']})")
    return out


def write_loop(w, lp, what):
    """The loop's table: one row per step."""
    rep = lp.get("repeatability_mm")
    w(f"The loop, `stiff diagnose --auto` from the nominal model (registration and tool) on "
      f"{what}" + (f", with the robot's stated repeatability (`--repeatability {rep:g}`)"
                   if rep else "") + ", as a user runs it (docs/diagnosis.md, rule 5). The "
      "held-out poses are the validation poses and the calibration poses cross-validated "
      "(5 folds):")
    w("")
    w("| step | added | parameters | calibration RMS [mm] | validation mean [mm] | max [mm] | "
      "RMS [mm] | cross-validated mean [mm] | verdict |")
    w("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for i, st in enumerate(lp["steps"]):
        v = st["validation"]
        c = st.get("cross_validated")
        cv = f"{c['mean_mm']:.4f} ± {c['ci95_mean_mm']:.4f}" if c else "-"
        w(f"| {i} | {st['added'] or '-'} | {st['parameters']} | {st['fit_rms_mm']:.4f} | "
          f"{v['mean_mm']:.4f} ± {v['ci95_mean_mm']:.4f} | {v['max_mm']:.4f} | "
          f"{v['rms_mm']:.4f} | {cv} | {st['verdict']} |")
    w("")
    w(f"Final model: {lp['final_model']} ({lp['final_verdict']}), {lp['seconds']:.0f} s.")
    for note in lp.get("notes", []):
        w(f"The diagnosis notes: {note}.")
    w("")


def summary(e):
    """Position errors [mm] or (position [mm], orientation [deg]) per pose."""
    a = None
    if isinstance(e, tuple):
        e, a = e
    e = np.asarray(e)
    out = {"mean_mm": float(e.mean()), "max_mm": float(e.max()),
           "rms_mm": float(np.sqrt(np.mean(e ** 2))), "n": int(e.size),
           "ci95_mean_mm": float(1.96 * e.std(ddof=1) / math.sqrt(e.size)),
           "per_pose_mm": [round(float(v), 5) for v in e]}
    if a is not None:
        out.update({"mean_deg": float(np.mean(a)), "max_deg": float(np.max(a))})
    return out


def product_ur5(folds=5, seed=0):
    out = {}
    grid, test = REAL / "ur5" / "ur5_grid.csv", REAL / "ur5" / "ur5_random.csv"
    n = len(ref.read_absolute(grid)["q"])
    with tempfile.TemporaryDirectory() as tmp:
        for name in ref.UR5_MODELS:
            model = MODELS[name]
            e, st = product_errors("ur5", grid, test, model, tmp)
            res = {"calibration": st, "validation": summary(e)}
            perm = np.random.default_rng(seed).permutation(n)
            errs = []
            for k in range(folds):
                te = np.sort(perm[k::folds])
                tr = np.setdiff1d(perm, te)
                write_rows(grid, tr, os.path.join(tmp, "tr.csv"))
                write_rows(grid, te, os.path.join(tmp, "te.csv"))
                ek, _ = product_errors("ur5", os.path.join(tmp, "tr.csv"),
                                       os.path.join(tmp, "te.csv"), model, tmp)
                errs.append(ek)
            res["cv"] = summary(np.concatenate(errs))
            out[name] = res
    return out


def product_ur10(seed=0):
    out = {}
    C = REAL / "ur10" / ref.UR10_SERIES["C"]
    n = len(ref.read_absolute(C)["q"])
    perm = np.random.default_rng(seed).permutation(n)
    tr, te = np.sort(perm[:n // 2]), np.sort(perm[n // 2:])
    with tempfile.TemporaryDirectory() as tmp:
        write_rows(C, tr, os.path.join(tmp, "tr.csv"))
        write_rows(C, te, os.path.join(tmp, "te.csv"))
        for name in ref.UR10_MODELS:
            model = ur10_model(name)
            e, st = product_errors("ur10", os.path.join(tmp, "tr.csv"),
                                   os.path.join(tmp, "te.csv"), model, tmp, degrees=True)
            out[name] = {"half_C": {"calibration": st, "validation": summary(e)}}
            out[name].update(product_transfer(C, model, seed, tmp))
    return out


DRAWS, DRAWS_OF = 10, ("B", "D")  # the 15-pose registration: draws, series


def product_transfer(C, model, seed, tmp):
    """(a): calibrate on all of C, then register each other series (a new tracker placement)
    with `stiff identify --start C.json --refit registration` on the reference's random 20 %
    of its rows (or 15 poses), and evaluate on the rest."""
    exe = stiff_exe()
    cfit = os.path.join(tmp, "C.json")
    _run([exe, "identify", "--robot", "ur10", "--data", str(C), "--model", model, "-o", cfit])
    out = {"C": {"calibration": {"parameters": json.loads(Path(cfit).read_text())["fit"]["rank"]}}}
    # The registration alone (the issue's protocol), and with the probe's frame on the flange
    # refitted too (a probe re-mounted for the new set-up).
    refits = [("", "registration")] + ([(" probe", "registration+tool_orientation")]
                                       if "tool_orientation" in model else [])

    def registered(S, reg, ev, refit):
        """Summary of the errors on rows ev of S after refitting `refit` on rows reg."""
        rp, ep = os.path.join(tmp, "reg.csv"), os.path.join(tmp, "ev.csv")
        write_rows(S, reg, rp)
        write_rows(S, ev, ep)
        fit, pred = os.path.join(tmp, "reg.json"), os.path.join(tmp, "ev_pred.csv")
        _run([exe, "identify", "--robot", "ur10", "--data", rp, "--start", cfit,
              "--refit", refit, "-o", fit])
        s = summary(predicted_errors("ur10", fit, ep, pred, True))
        s.pop("per_pose_mm")  # thousands of poses: the summary only
        return s

    for k in ("B", "D", "A"):
        S = REAL / "ur10" / ref.UR10_SERIES[k]
        if not S.exists():
            continue
        n = len(ref.read_absolute(S)["q"])
        for label, count in (("20%", None), ("15 poses", 15)):
            r = np.random.default_rng(seed + 1).permutation(n)  # the reference's split
            nreg = int(round(0.2 * n)) if count is None else count
            reg, ev = np.sort(r[:nreg]), np.sort(r[nreg:])
            for key, refit in refits:
                out[f"{k} ({label}){key}"] = registered(S, reg, ev, refit)
        if k not in DRAWS_OF:
            continue
        # Which 15 poses register a set-up matters more than the evaluation's own spread:
        # further draws, the same as the reference's (draw 0 is the split above).
        for key, refit in refits:
            main = out[f"{k} (15 poses){key}"]
            mm, deg = [main["mean_mm"]], [main.get("mean_deg")]
            for reg, ev in ref.fifteen_pose_draws(n, DRAWS, seed, first=1):
                s = registered(S, reg, ev, refit)
                mm.append(s["mean_mm"])
                deg.append(s.get("mean_deg"))
            out[f"{k} (15 poses, draws){key}"] = {"mean_mm": mm, "mean_deg": deg}
    return out


# ----------------------------------------------------------------------------- report

def _f(v, spec=".4f"):
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:{spec}}"


def _ci(s):
    return f"{_f(s['mean_mm'])} ± {_f(s['ci95_mean_mm'], '.4f')}" if s.get("ci95_mean_mm") \
        else _f(s["mean_mm"])


def transfer_table(w, who, r, degrees):
    """The UR10 (a) table of `who`'s results r[model]["B (20%)"] etc."""
    deg = " mean [deg] |" if degrees else ""
    w(f"| model ({who}) | parameters | series | registration from | mean [mm] | max [mm] | "
      f"RMS [mm] |{deg}")
    w("| --- " * (8 if degrees else 7) + "|")
    for n in ref.UR10_MODELS:
        if n not in r:
            continue
        for k in ("B", "D", "A"):
            for lab in ("20%", "15 poses"):
                v = r[n].get(f"{k} ({lab})")
                if v is None:
                    continue
                w(f"| {n} | {r[n]['C']['calibration']['parameters']} | {k} | "
                  f"{lab.replace('%', ' %')} | {_ci(v)} | {_f(v['max_mm'])} | "
                  f"{_f(v['rms_mm'])} |" + (f" {_f(v.get('mean_deg'))} |" if degrees else ""))
    w("")


def draws_table(w, r, pr):
    """The 15-pose registration over several random draws of the 15 poses."""
    key = lambda k: f"{k} (15 poses, draws)"
    rows = [(n, k) for n in ref.UR10_MODELS for k in "BDA"
            if key(k) in r.get(n, {}) and key(k) in pr.get(n, {})]
    if not rows:
        return

    def cell(v):
        if v is None:
            return "-"
        mm, deg = np.asarray(v["mean_mm"]), [d for d in v["mean_deg"] if d is not None]
        d = f", {np.mean(deg):.4f} deg" if deg else ""
        return f"{mm.mean():.4f} ({mm.min():.4f}-{mm.max():.4f}){d}"

    nd = len(r[rows[0][0]][key(rows[0][1])]["mean_mm"])
    w(f"Which 15 poses register a set-up matters more than the evaluation's spread (the ± above): "
      f"over {nd} random draws of the 15 poses (the first is the split above), the mean of the "
      "draws' mean errors, their range, and the mean orientation error:")
    w("")
    w("| model | series | reference [mm] | stiff, registration [mm] | "
      "stiff, probe refitted [mm] |")
    w("| --- | --- | --- | --- | --- |")
    for n, k in rows:
        w(f"| {n} | {k} | {cell(r[n][key(k)])} | {cell(pr[n][key(k)])} | "
          f"{cell(pr[n].get(key(k) + ' probe'))} |")
    w("")


def plot_ur5(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    names = ("nominal",) + ref.UR5_MODELS
    r = res["reference"]["ur5"]
    val = [r[n]["validation"]["per_pose_mm"] for n in names]
    ax[0].boxplot(val, showmeans=True)
    ax[0].set_xticks(range(1, len(names) + 1),
                     ["nominal"] + [n.replace("geometry+", "+").replace("+", "\n+ ")
                                    for n in names[1:]], fontsize=7)
    ax[0].set_yscale("log")
    ax[0].axhline(0.1, color="grey", ls="--", lw=0.8)
    ax[0].text(len(names) + 0.4, 0.1, "repeatability", va="bottom", ha="right", fontsize=8, color="grey")
    ax[0].set_ylabel("position error [mm]")
    ax[0].set_title("UR5: 20 random test poses (reference)", fontsize=10)
    for n in ref.UR5_MODELS:
        e = np.sort(r[n]["cv"]["per_pose_mm"])
        ax[1].plot(e, np.arange(1, e.size + 1) / e.size, label=n)
    ax[1].set_xlabel("position error [mm]")
    ax[1].set_ylabel("fraction of grid poses")
    ax[1].set_title("UR5: 5-fold cross-validation on the grid", fontsize=10)
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_ur10(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    r = res["reference"]["ur10"]
    cases = [k for k in ("half_C", "B (20%)", "D (20%)", "A (20%)") if k in r["geometry"]]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    names = [n for n in ref.UR10_MODELS if n in r]
    w = 0.8 / len(names)
    for j, n in enumerate(names):
        m = [(r[n][k]["validation"] if k == "half_C" else r[n][k])["mean_mm"] for k in cases]
        ax.bar(np.arange(len(cases)) + (j - (len(names) - 1) / 2) * w, m, w, label=n)
    ax.set_yscale("log")
    ax.set_xticks(range(len(cases)), ["C: other half" if k == "half_C" else
                                      f"series {k[0]}\n(registration: 20 %)" for k in cases])
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_ylabel("mean position error [mm]")
    ax.set_title("UR10: calibrated on series C (reference)", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _clean(msg):
    return re.sub(r"\S*/\S*?:(\d+:)*\s*", "", msg)


def write_doc(res):
    FIGS.mkdir(parents=True, exist_ok=True)
    L = []
    w = L.append
    w("# Calibration on real laser-tracker data")
    w("")
    w("Absolute measurements of two real robots, shipped in `examples/real/` (MIT licence, "
      "citations in its README), calibrated with a model that grows step by step: geometry "
      "(the registration of each session, the tool, joint offsets, kinematic errors with "
      "Hayati parameters at parallel axes), then gravity compliance with lumped parameters, "
      "then transmission errors periodic in the joint angles (first and second harmonic). "
      "Regenerate this page with")
    w("")
    w("```")
    w(".venv/bin/python bench/real_data.py")
    w("```")
    w("")
    w("Every number below is measured by that command. The tables marked *reference* come "
      "from an independent numpy/scipy implementation of the same kind of model "
      "(`bench/peers/absolute_ref.py`: standard DH plus Hayati's beta at parallel axes, a "
      "registration per session, the tool, gravity compliance as lumped gravity-torque "
      "regressors from the nominal geometry; identifiable parameters chosen by column-pivoted "
      "QR of the unit-column Jacobian with a relative pivot tolerance of 1e-3, columns whose "
      "remaining norms tie within the finite-difference noise taken in column order, so that "
      "the held set does not depend on the BLAS's round-off; "
      "`scipy.optimize.least_squares` with its finite-difference Jacobian). They are what "
      "stiff's own calibration is checked against.")
    w("")
    w("stiff runs with its default identifiability setting (docs/identifiability.md): the "
      "structural rank test; before the solve, on the linearised start, a parameter whose "
      "standard error exceeds ten typical magnitudes is held; at the solution, every fitted "
      "parameter whose standard error exceeds 100 typical magnitudes and a third of its "
      "distance from the null value is held too (`--max-relative-se 100`, the default).")
    w("")
    w("Errors are Euclidean distances between the measured and the predicted target position; "
      "± is the 95 % confidence interval of the mean (1.96 s / sqrt(n)).")
    w("")
    prod = res.get("product", {})

    # ---- UR5
    if "ur5" in res["reference"]:
        r = res["reference"]["ur5"]
        w("## UR5 (Jacobi 2025)")
        w("")
        w(f"{r['calibration_rows']} grid poses for calibration, {r['validation_rows']} random "
          "poses for validation, one session (the authors registered the tracker to the base). "
          "The UR5's repeatability is ±0.1 mm; the 20 test poses resolve a mean only to about "
          "±0.013 mm, so models are compared by 5-fold cross-validation on the grid as well.")
        w("")
        w("| model (reference) | parameters | calibration RMS [mm] | validation mean [mm] | "
          "max [mm] | RMS [mm] | 5-fold CV mean [mm] | CV RMS [mm] |")
        w("| --- | --- | --- | --- | --- | --- | --- | --- |")
        for n in ("nominal",) + ref.UR5_MODELS:
            c, v = r[n]["calibration"], r[n]["validation"]
            cv = r[n].get("cv")
            label = "nominal (registration and tool only)" if n == "nominal" else n
            w(f"| {label} | {c['parameters']} | {_f(c['rms_mm'])} | {_ci(v)} | "
              f"{_f(v['max_mm'])} | {_f(v['rms_mm'])} | {_ci(cv) if cv else '-'} | "
              f"{_f(cv['rms_mm']) if cv else '-'} |")
        w("")
        if "ur5" in prod and "skipped" not in prod["ur5"]:
            p = prod["ur5"]
            w("| model (stiff) | parameters | calibration RMS [mm] | validation mean [mm] | "
              "max [mm] | RMS [mm] | 5-fold CV mean [mm] | identify time [s] |")
            w("| --- | --- | --- | --- | --- | --- | --- | --- |")
            for n in ref.UR5_MODELS:
                c, v, cv = p[n]["calibration"], p[n]["validation"], p[n]["cv"]
                w(f"| {n} | {c['parameters']} | {_f(c['rms_mm'])} | {_ci(v)} | "
                  f"{_f(v['max_mm'])} | {_f(v['rms_mm'])} | {_ci(cv)} | "
                  f"{_f(c['seconds'], '.3f')} |")
            w("")
        elif "ur5" in prod:
            w(f"stiff: not run ({_clean(prod['ur5']['skipped'])}).")
            w("")
        if res.get("loop", {}).get("ur5"):
            write_loop(w, res["loop"]["ur5"], "the grid, validated on the 20 random poses")
        cvs = {n: np.array(r[n]["cv"]["per_pose_mm"]) for n in ref.UR5_MODELS}
        best = min(cvs, key=lambda n: cvs[n].mean())
        w("Paired differences of the cross-validated errors (same folds, same poses; mean "
          "± 95 % interval, negative = better):")
        w("")
        w("| step | change of the CV mean [mm] |")
        w("| --- | --- |")
        for a_, b_ in (("geometry", "geometry+gravity"), ("geometry", "geometry+harmonics"),
                       ("geometry+gravity", "geometry+gravity+harmonics"),
                       ("geometry+harmonics", "geometry+gravity+harmonics")):
            d = cvs[b_] - cvs[a_]
            w(f"| {a_} -> {b_} | {d.mean():+.4f} ± {1.96 * d.std(ddof=1) / math.sqrt(d.size):.4f} |")
        w("")
        w(f"The best model by cross-validation is {best}: {cvs[best].mean():.4f} mm mean, "
          f"{np.sqrt(np.mean(cvs[best] ** 2)):.4f} mm RMS on poses it was not fitted to, "
          "below the UR5's ±0.1 mm repeatability: what remains is at the robot's "
          "repeatability, and no candidate of this list is supported beyond it.")
        w("")
        g = r["geometry"]["calibration"]
        w(f"Held by the reference's rank test (geometry): {', '.join(g['held'])}. The target "
          "sits almost on the axis of joint 6, so that joint's offset and the tilt of the last "
          "axes are not determined by positions alone; joint 1's offset and the registration's "
          "turn about the base z axis are one parameter, as are the base's height and the "
          "offsets along axis 1; a translation along parallel axes 2-3-4 is one parameter, not "
          "three. Which member of such a combination is held is a tie, taken in column order.")
        w("")
        w("stiff runs with its built-in `ur5` (the URDF of examples/robots: its base_link is "
          "the DH base turned 180 deg about z and its tip frame is turned by a constant "
          "rotation; the registration and the tool take both up), the reference with "
          "Universal Robots' DH table of the same arm.")
        w("")
        w("Published (Jacobi 2025, on the same 20 test poses): mean 2.5664 mm uncalibrated, "
          "0.1549 mm after calibration of a modified DH model combined with a neural network "
          "for the residual. The uncalibrated figure is against the authors' nominal model and "
          "registration; the nominal row above refits the registration and the tool point to "
          "the grid, which already removes most of that.")
        w("")
        w("![UR5](real-data/ur5.png)")
        w("")

    # ---- UR10
    if "ur10" in res["reference"]:
        r = res["reference"]["ur10"]
        rows = r["rows"]
        w("## UR10 (Landgraf et al. 2021)")
        w("")
        w("Four series, each its own tracker set-up (session), with the T-Mac's 6-D pose: C "
          f"random poses ({rows.get('C')} rows), B joint configurations ({rows.get('B')}), "
          f"D ISO cubes ({rows.get('D')}), A a grid ({rows.get('A')} rows shipped: every 5th "
          "of 11911). The reference weighs orientation residuals 1 mm per mrad; stiff fits the "
          "probe's frame on the flange (`tool_orientation`) and estimates the weight from the "
          "residuals (docs/identifiability.md), about 0.5 mm per mrad here.")
        w("")
        if res.get("loop", {}).get("ur10"):
            write_loop(w, res["loop"]["ur10"],
                       "series C, validated on series B (another set-up, registered by the "
                       "diagnosis from a fifth of its rows, scored on the rest)")
        w("(b) Calibrated on a random half of C, validated on the other half:")
        w("")
        w("| model (reference) | parameters | calibration RMS [mm] | validation mean [mm] | "
          "max [mm] | RMS [mm] | mean [deg] |")
        w("| --- | --- | --- | --- | --- | --- | --- |")
        for n in ("nominal",) + ref.UR10_MODELS:
            if n not in r:
                continue
            c, v = r[n]["half_C"]["calibration"], r[n]["half_C"]["validation"]
            label = "nominal (registration and tool only)" if n == "nominal" else n
            w(f"| {label} | {c['parameters']} | {_f(c['rms_mm'])} | {_ci(v)} | "
              f"{_f(v['max_mm'])} | {_f(v['rms_mm'])} | {_f(v.get('mean_deg'))} |")
        w("")
        if "ur10" in prod and "skipped" not in prod["ur10"]:
            p = prod["ur10"]
            w("stiff fits the same models with `tool_orientation` (`stiff identify --model "
              "registration+tool+tool_orientation+...`), on the positions and the orientations:")
            w("")
            w("| model (stiff) | parameters | calibration RMS [mm] | validation mean [mm] | "
              "max [mm] | RMS [mm] | mean [deg] | identify time [s] |")
            w("| --- | --- | --- | --- | --- | --- | --- | --- |")
            for n in ref.UR10_MODELS:
                c, v = p[n]["half_C"]["calibration"], p[n]["half_C"]["validation"]
                w(f"| {n} | {c['parameters']} | {_f(c['rms_mm'])} | {_ci(v)} | "
                  f"{_f(v['max_mm'])} | {_f(v['rms_mm'])} | {_f(v.get('mean_deg'))} | "
                  f"{_f(c['seconds'], '.3f')} |")
            w("")
        elif "ur10" in prod:
            w(f"stiff: not run ({_clean(prod['ur10']['skipped'])}).")
            w("")
        w("(a) Calibrated on all of C, then each other series with only its registration "
          "refitted, from a random 20 % of its rows (or 15 poses), evaluated on the rest:")
        w("")
        transfer_table(w, "reference", r, degrees=True)
        pr = prod.get("ur10", {})
        if all(n in pr and "B (20%)" in pr[n] for n in ref.UR10_MODELS):
            w("stiff (the models above with `tool_orientation`: positions and orientations): "
              "calibrated on all of C (`stiff identify`), then each series registered "
              "to it with `stiff identify --start C.json --refit registration` on the same "
              "rows as the reference, evaluated on the same rest:")
            w("")
            transfer_table(w, "stiff", pr, degrees=True)
            probe = {n: {"C": pr[n]["C"], **{k[:-len(" probe")]: v for k, v in pr[n].items()
                                             if k.endswith(" probe")}}
                     for n in ref.UR10_MODELS if n in pr}
            if any(len(v) > 1 for v in probe.values()):
                w("The same with the probe's frame on the flange refitted as well (`--refit "
                  "registration+tool_orientation`), as for a probe re-mounted in the new "
                  "set-up. Series D's poses (ISO cubes) nearly share one orientation: refitting "
                  "the registration alone, its rotation takes up the model's orientation error "
                  "there from the orientation residuals, which costs positions elsewhere; the "
                  "probe's frame takes it up instead:")
                w("")
                transfer_table(w, "stiff, probe refitted", probe, degrees=True)
            draws_table(w, r, pr)
        if all(n in r for n in ref.UR10_MODELS):
            hv = lambda n: r[n]["half_C"]["validation"]["mean_mm"]
            tr = lambda n: [r[n][f"{k} (20%)"]["mean_mm"] for k in "BDA" if f"{k} (20%)" in r[n]]
            g, gg, gh = "geometry", "geometry+gravity", "geometry+gravity+harmonics"
            w(f"Within series C the three models differ little ({hv(g):.3f}, {hv(gg):.3f}, "
              f"{hv(gh):.3f} mm): C alone cannot tell them apart, and the largest model looks "
              "best. Carried to the other set-ups they part: gravity compliance lowers the "
              f"error on B, D, A from {min(tr(g)):.2f}-{max(tr(g)):.2f} mm to "
              f"{min(tr(gg)):.2f}-{max(tr(gg)):.2f} mm, so it is what transfers; joint "
              f"harmonics fitted on C raise it to {min(tr(gh)):.1f}-{max(tr(gh)):.1f} mm: "
              "they fit C's poses, not the robot, and a calibration must refuse them.")
            lp = res.get("loop", {}).get("ur10")
            if lp:
                added = [st["added"] for st in lp["steps"] if st["added"]]
                refused = "harmonic" not in added
                w("")
                w("The loop above finds this from the data: validated on series B as a new "
                  f"set-up, it adds {', '.join(added)}" +
                  (" and refuses the harmonics." if refused else
                   " (harmonics included)."))
            w("")
        w("Published (Landgraf et al. 2021, IEEE CASE): the same four series, with the "
          "authors' own evaluation protocol (a hybrid of a kinematic calibration and neural "
          "networks); their figures are not on the splits above and are not repeated here.")
        w("")
        w("![UR10](real-data/ur10.png)")
        w("")
    w("## Speed")
    w("")
    w("| run | reference: rank test + fit [s] | of which least_squares [s] | least_squares "
      "iterations (nfev) | stiff identify, command [s] | stiff identify, library [s] | "
      "least_squares / library |")
    w("| --- | --- | --- | --- | --- | --- | --- |")
    for ds, key in (("ur5", None), ("ur10", "half_C")):
        if ds not in res["reference"]:
            continue
        for n in (ref.UR5_MODELS if ds == "ur5" else ref.UR10_MODELS):
            rr = res["reference"][ds][n]
            c = rr[key]["calibration"] if key else rr["calibration"]
            pp = prod.get(ds, {})
            ps = pl = ratio = "-"
            if n in pp:
                pc = pp[n][key]["calibration"] if key else pp[n]["calibration"]
                ps = _f(pc["seconds"], ".3f")
                lib_s = pc.get("library_seconds")
                pl = _f(lib_s, ".3f")
                if lib_s and c.get("least_squares_seconds"):
                    ratio = f"{c['least_squares_seconds'] / lib_s:.1f}"
            w(f"| {ds} {n}{' (half of C)' if key else ''} | {_f(c['seconds'], '.2f')} | "
              f"{_f(c.get('least_squares_seconds'), '.2f')} | {c.get('nfev', '-')} | {ps} | "
              f"{pl} | {ratio} |")
    w("")
    w("The ratio follows the reference's iterations: where its held set leaves a nearly "
      "dependent combination free (the joint harmonics of the UR5), its finite-difference "
      "least_squares takes tens of iterations, each a full finite-difference Jacobian; stiff "
      "solves the same kind of model in a handful.")
    w("")
    if res.get("pooled"):
        w("At about 10^4 rows: the four UR10 series pooled (positions only, one registration "
          "per series), same run:")
        w("")
        w("| model | rows | parameters (reference / stiff) | reference least_squares [s] | "
          "least_squares iterations (nfev) | stiff identify, library [s] | "
          "least_squares / library |")
        w("| --- | --- | --- | --- | --- | --- | --- |")
        for n, v in res["pooled"].items():
            lib_s, ls = v.get("library_seconds"), v["reference"]["least_squares_seconds"]
            w(f"| {n} | {v['rows']} | {v['reference']['parameters']} / "
              f"{v.get('stiff_parameters', '-')} | {ls:.2f} | {v['reference'].get('nfev', '-')} | "
              f"{_f(lib_s, '.2f')} | {(ls / lib_s if lib_s else float('nan')):.1f} |")
        w("")
        per = []
        for n, v in res["pooled"].items():
            lib_s, ls = v.get("library_seconds"), v["reference"]["least_squares_seconds"]
            if lib_s:
                per.append(f"{lib_s * 1e4 / v['rows']:.2f} s for {n} ({ls / lib_s:.0f} times "
                           f"scipy)")
        if per:
            w("Scaled to 10^4 rows, stiff's library time is " + " and ".join(per) + ". An "
              "absolute row's Jacobian takes one evaluation of the model: the registration, the "
              "joint offsets, the axis errors, the lumped self-weight and the 6-D probe's frame "
              "give their columns analytically from the tangents of the corrected chain that "
              "evaluation keeps (positions and, with a 6-D probe, orientations), and automatic "
              "differentiation carries only the tool's offset and the registration's maps of "
              "the position and orientation in the same pass; a calibration evaluates about five "
              "Jacobians (at the start and once per solver step; the statistics reuse the last) "
              "and factors the tall Jacobian once, for the identifiability test at the start. "
              "Where rows state their noise, and on a 6-D probe's poses, it fits again once the "
              "weights are estimated from the residuals (the model's error beside the stated "
              "noise, the orientation residuals' weight: variance components, "
              "docs/identifiability.md): on series C 7 Jacobians for geometry and 10 for "
              "geometry+gravity with the orientations, 10 and 11 with the positions alone.")
            w("")
    w("Both run on one thread (the reference's BLAS is limited to one, as stiff's solver uses "
      "one) and are timed in CPU seconds of this process, which a busy machine disturbs less "
      "than wall time. The reference's time covers its identifiability test and the least-squares fit "
      "(scipy's finite-difference Jacobian); stiff's command time is the wall time of "
      "`stiff identify` including the start of the process (Python, about 0.2 s), its library "
      "time the identification alone (`stiff.identify` in this process, best of three: "
      "identifiability tests, solve, statistics). Both are measured on the same machine in "
      "the same run; a loaded machine slows both.")
    w("")
    DOC.write_text("\n".join(L))
    if "ur5" in res["reference"]:
        plot_ur5(res, FIGS / "ur5.png")
    if "ur10" in res["reference"]:
        plot_ur10(res, FIGS / "ur10.png")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", choices=["ur5", "ur10", "pooled", "loop"])
    ap.add_argument("--no-product", action="store_true", help="run the reference alone")
    ap.add_argument("--doc-only", action="store_true",
                    help="rewrite the document and plots from the last results, run nothing")
    a = ap.parse_args(argv)
    res = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    res.setdefault("reference", {})
    res.setdefault("product", {})
    for ds in ("ur5", "ur10"):
        if a.doc_only or (a.only and ds != a.only):
            continue
        t = time.perf_counter()
        res["reference"][ds] = ref.study_ur5(REAL) if ds == "ur5" else ref.study_ur10(REAL, draws=DRAWS, draws_of=DRAWS_OF)
        print(f"reference {ds}: {time.perf_counter() - t:.1f} s")
        if a.no_product:
            res["product"][ds] = {"skipped": "not asked (--no-product)"}
            continue
        try:
            res["product"][ds] = product_ur5() if ds == "ur5" else product_ur10()
        except (ProductUnavailable, FileNotFoundError, KeyError) as e:
            # No machine paths in the document: the reason, not where it happened.
            why = re.sub(r"\S*/\S*?:(\d+:)*\s*", "", str(e))
            msg = f"this build of stiff cannot calibrate absolute data: {why}"
            print(f"stiff {ds}: skipped, {msg}")
            res["product"][ds] = {"skipped": msg}
    if not a.doc_only and not a.no_product and a.only in (None, "pooled"):
        res["pooled"] = speed_pooled()
    if not a.doc_only and not a.no_product and a.only in (None, "loop"):
        res["loop"] = loops()
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(res, indent=1) + "\n")
    write_doc(res)
    for ds, r in res["reference"].items():
        for n in (ref.UR5_MODELS if ds == "ur5" else ref.UR10_MODELS):
            if ds == "ur5":
                v = r[n]["validation"]
                print(f"reference ur5 {n}: {r[n]['calibration']['parameters']} parameters, "
                      f"validation mean {v['mean_mm']:.4f} max {v['max_mm']:.4f} mm, "
                      f"CV mean {r[n]['cv']['mean_mm']:.4f} mm")
            else:
                v = r[n]["half_C"]["validation"]
                print(f"reference ur10 {n}: half C mean {v['mean_mm']:.4f} mm "
                      f"{v.get('mean_deg', float('nan')):.4f} deg; " + "; ".join(
                          f"{k} {r[n][k]['mean_mm']:.4f} mm" for k in r[n]
                          if k not in ("half_C", "C") and "draws" not in k))
    print(f"wrote {DOC.relative_to(ROOT)}, {RESULTS.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
