#!/usr/bin/env python3
"""Score `stiff diagnose` on a directory of scenarios with known truth (docs/diagnosis.md,
"Scoring on independent data").

Each scenario folder holds calib.csv, valid.csv and truth.json (`type`, `expected.verdict`,
`expected.effects`, `true_class_refit_valid_um.axis_um`); index.json at the top lists them.
Every scenario runs `stiff diagnose --auto --model joint` as given; with `--noise both` (the
default) a file that states its noise (a `sigma_d_mm` column, force-error metadata) is run a
second time with the noise removed, so that each scenario counts with and without it.

    bench/diagnosis_score.py [--data DIR] [--sets base,sigma] [--types c,d] [--seeds 0-4]
                             [--noise given|hidden|both] [--jobs 2] [--json out.json]

Skips cleanly (exit 0, a message) when the data directory does not exist.

Per type it reports: right (missing_effect naming the expected effect, or ambiguous with it in
the group; for controls `adequate`; for effects outside the library no confident claim, i.e.
`unexplained` or `ambiguous`), ambiguous, confident wrong (missing_effect naming an effect that
is not there), and the median ratio of the validation RMS of the model the loop ends with to
the RMS a right model reaches (`true_class_refit_valid_um`). For two effects at once the loop's
final model must contain both.
"""
import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The scenario directory: --data, else $STIFF_DIAGNOSIS_DATA.
DEFAULT_DATA = os.environ.get("STIFF_DIAGNOSIS_DATA", "")
STIFF = os.path.join(ROOT, ".venv", "bin", "stiff")
ROBOT = os.path.join(ROOT, "examples", "robots", "rokae.yaml")
NOISE_META = ("force_relative", "force_absolute_n", "tracker_sigma_m")


def parse_seeds(text):
    out = set()
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.update(range(int(a), int(b) + 1))
        elif part:
            out.add(int(part))
    return out


def hide_noise(src, dst):
    """Copy a measurement CSV without its noise statement (sigma_d column, noise metadata)."""
    with open(src) as f:
        lines = f.read().splitlines()
    meta = [l for l in lines if l.startswith("#")]
    body = [l for l in lines if not l.startswith("#") and l.strip()]
    meta = [l for l in meta if l[1:].split(":")[0].strip().lower() not in NOISE_META]
    rows = list(csv.reader(body))
    header = rows[0]
    keep = [i for i, h in enumerate(header) if not h.startswith("sigma_d")]
    with open(dst, "w", newline="") as f:
        f.write("\n".join(meta) + "\n")
        w = csv.writer(f, lineterminator="\n")
        for r in rows:
            w.writerow([r[i] for i in keep])


def states_noise(path):
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                if line[1:].split(":")[0].strip().lower() in NOISE_META:
                    return True
                continue
            return "sigma_d" in line
    return False


def run_one(folder, hidden, stiff, robot, tmp):
    calib, valid = os.path.join(folder, "calib.csv"), os.path.join(folder, "valid.csv")
    tag = os.path.basename(os.path.dirname(folder)) + "_" + os.path.basename(folder)
    if hidden:
        c2, v2 = os.path.join(tmp, tag + "_c.csv"), os.path.join(tmp, tag + "_v.csv")
        hide_noise(calib, c2)
        hide_noise(valid, v2)
        calib, valid = c2, v2
    out = os.path.join(tmp, tag + ("_h" if hidden else "_g") + ".json")
    cmd = [stiff, "diagnose", "--robot", robot, "--data", calib, "--validate", valid,
           "--model", "joint", "--auto", "--json", out]
    t0 = time.time()
    p = subprocess.run(cmd, capture_output=True, text=True)
    dt = time.time() - t0
    if p.returncode != 0:
        return {"error": (p.stderr.strip().splitlines() or ["?"])[-1], "seconds": dt}
    with open(out) as f:
        d = json.load(f)
    return {"json": d, "seconds": dt}


def classify(truth, d):
    """(outcome, named effects, final-model validation RMS ratio)."""
    exp = truth["expected"]
    verdict = d["verdict"]
    top = d["suggested_model"].split("+")[-1] if d.get("suggested_model") else None
    group = d.get("ambiguous_group") or []
    final = set(d.get("final_model", "joint").split("+")) - {"joint"}
    steps = d.get("steps") or []
    final_valid = steps[-1].get("validation_rms_m") if steps else None
    ref = truth.get("true_class_refit_valid_um", {}).get("axis_um")
    ratio = final_valid * 1e6 / ref if final_valid and ref else None
    want = exp.get("effects") or []
    if exp["verdict"] == "adequate":
        outcome = {"adequate": "right", "ambiguous": "ambiguous",
                   "missing_effect": "wrong"}.get(verdict, "miss")
    elif exp["verdict"] == "unexplained":
        outcome = {"unexplained": "right", "ambiguous": "right",
                   "missing_effect": "wrong"}.get(verdict, "miss")
    elif len(want) > 1:
        named = final | set(group)
        if verdict == "missing_effect" and set(want) <= final:
            outcome = "right"
        elif verdict in ("missing_effect", "ambiguous") and named & set(want):
            outcome = "partial"
        elif verdict == "missing_effect":
            outcome = "wrong"
        else:
            outcome = "miss"
    else:
        if verdict == "missing_effect":
            outcome = "right" if top in want else "wrong"
        elif verdict == "ambiguous":
            outcome = "right" if set(want) & set(group) else "ambiguous"
        else:
            outcome = "miss"
    return outcome, verdict, top, sorted(final), ratio


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA,
                    help="scenario directory (index.json and its folders); default "
                         "$STIFF_DIAGNOSIS_DATA")
    ap.add_argument("--sets", default="base,sigma,ool,oolsig",
                    help="comma-separated sets (folders of the data directory)")
    ap.add_argument("--types", default="", help="comma-separated types (default all)")
    ap.add_argument("--seeds", default="0-19", help="seed numbers, e.g. 0-4 or 0,3,7")
    ap.add_argument("--noise", choices=("given", "hidden", "both"), default="both")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--stiff", default=STIFF)
    ap.add_argument("--robot", default=ROBOT)
    ap.add_argument("--json", help="write every scenario's outcome here")
    ap.add_argument("--verbose", "-v", action="store_true")
    a = ap.parse_args()
    if not os.path.isdir(a.data) or not os.path.exists(os.path.join(a.data, "index.json")):
        where = a.data or "(none given: --data DIR or $STIFF_DIAGNOSIS_DATA)"
        print(f"diagnosis_score: no scenario data at {where}: skipped")
        return 0
    with open(os.path.join(a.data, "index.json")) as f:
        index = json.load(f)
    sets = set(a.sets.split(","))
    types = set(a.types.split(",")) if a.types else None
    seeds = parse_seeds(a.seeds)
    jobs = []
    for e in index:
        s, name = e["path"].split("/")
        seed = int(name.rsplit("_", 1)[1])
        if s not in sets or (types and e["type"] not in types) or seed not in seeds:
            continue
        folder = os.path.join(a.data, e["path"])
        given = states_noise(os.path.join(folder, "calib.csv"))
        modes = []
        if a.noise in ("given", "both"):
            modes.append(False)
        if a.noise in ("hidden", "both") and given:
            modes.append(True)
        if a.noise == "hidden" and not given:
            modes.append(False)
        for hidden in modes:
            jobs.append((e, folder, hidden, given and not hidden))
    results = []
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(a.jobs) as ex:
        futs = [(j, ex.submit(run_one, j[1], j[2], a.stiff, a.robot, tmp)) for j in jobs]
        for (e, folder, hidden, known), fut in futs:
            r = fut.result()
            with open(os.path.join(folder, "truth.json")) as f:
                truth = json.load(f)
            row = {"path": e["path"], "type": e["type"], "noise": "given" if known else "unknown",
                   "seconds": r["seconds"]}
            if "error" in r:
                row.update(outcome="error", verdict="error", error=r["error"])
            else:
                outcome, verdict, top, final, ratio = classify(truth, r["json"])
                row.update(outcome=outcome, verdict=verdict, top=top, final=final, ratio=ratio)
            results.append(row)
            if a.verbose:
                print(f"{row['path']:16s} {row['noise']:8s} {row['outcome']:9s} "
                      f"{row.get('verdict')} {row.get('top')} final={row.get('final')} "
                      f"ratio={row.get('ratio')}", flush=True)
    # Per set/type/noise table.
    keys = sorted({(r["path"].split("/")[0], r["type"], r["noise"]) for r in results})
    print(f"{'set':7s} {'type':9s} {'noise':8s} {'n':>3s} {'right':>6s} {'ambig':>6s} "
          f"{'wrong':>6s} {'miss':>5s} {'err':>4s} {'ratio_med':>9s} {'ratio_max_right':>15s}")
    for k in keys:
        rs = [r for r in results if (r["path"].split("/")[0], r["type"], r["noise"]) == k]
        c = {o: sum(r["outcome"] == o for r in rs)
             for o in ("right", "ambiguous", "wrong", "miss", "partial", "error")}
        ratios = [r["ratio"] for r in rs if r.get("ratio")]
        rr = [r["ratio"] for r in rs if r.get("ratio") and r["outcome"] == "right"]
        med = f"{statistics.median(ratios):.3f}" if ratios else "-"
        mx = f"{max(rr):.3f}" if rr else "-"
        miss = c["miss"] + c["partial"]
        print(f"{k[0]:7s} {k[1]:9s} {k[2]:8s} {len(rs):3d} {c['right']:6d} {c['ambiguous']:6d} "
              f"{c['wrong']:6d} {miss:5d} {c['error']:4d} {med:>9s} {mx:>15s}")
    secs = [r["seconds"] for r in results]
    print(f"{len(results)} runs in {time.time() - t0:.0f} s "
          f"(median {statistics.median(secs) if secs else 0:.2f} s per run)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
