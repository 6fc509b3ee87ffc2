"""Make scenarios with effects outside the library from a scenario directory's controls.

The development scenarios have two effects outside the library (a pedestal tilt and a joint
stiffness that varies with another joint's angle). This script adds other physical effects
that no candidate has the form of to the displacements of the control scenarios (type `none`)
of a directory laid out as bench/diagnosis_score.py reads it, so that their noise and base
compliance are the independent simulator's, and writes a directory that the scoring harness
reads (expected verdict: no confident claim):

  base_shift   the arm shifting as a whole under the force (a compliant base plate):
               d += C_b F, C_b symmetric positive definite in the base frame, 0.8-2.5 um/N
  angle_joint  joint 3's compliance varying with its own angle (a reducer whose stiffness
               changes over the output turn): d += J_3 c(q3) tau_3, c = a cos(2 q3 + phi)
  k<j>q<k>     joint j's compliance varying with joint k's angle, a cos(q_k + phi) (e.g.
               k3q2: the forearm's reducer stiffer as the shoulder turns; not in the default set)
  warmup       the joints' compliance growing over the session (a reducer's lubricant warming
               up): d += s (i / N) J C J^T F, row i of N, C the control's fitted compliances
  growth       thermal growth of the arm between the unloaded and the loaded pass: d += k P,
               k proportional to the session's length (the library's drift is a translation)
  sensor_level a force sensor whose gain changes with the load's level (its non-linearity):
               the force is read as F (1 + g), g = s (|F| - F0) / F0, s of either sign, F0
               the calibration rows' mean |F|; the arm deflects by C F / (1 + g), about
               C F (1 - g), with C the control's compliances
  sensor_offset  a zero offset of the force reading in the sensor (flange) frame: the force
               is read as F + R b, so the arm deflects by C (F_read - R b), b of a random
               direction (a sensor not tared, or its zero drifted)
  sensor_offset_base  the same offset fixed in the base frame (a load cell's bias under a
               fixture): F + b

Usage:
  .venv/bin/python bench/outside_probes.py --data DIR --out /tmp/probes --seeds 0-9
  .venv/bin/python bench/diagnosis_score.py --data /tmp/probes --sets base,sigma --noise given

The effect's RMS is set to `--size` (default 55 um per axis on the calibration rows, about
1.8 times the development data's noise), the same scale on the validation rows. A force
sensor's cross-talk is in the library (force_frame): bench/form_probes.py force_crosstalk,
force_crosstalk_base. Each scenario's truth.json records the effect's parameters and RMS.
Needs the `stiff` Python package and numpy.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import sys

import numpy as np

KINDS = ("base_shift", "angle_joint", "growth", "warmup",
         "sensor_level", "sensor_offset", "sensor_offset_base")
DESCRIPTION = {
    "base_shift": "outside the library: the arm shifts as a whole under the force (base plate "
                  "compliance fixed in the base frame)",
    "angle_joint": "outside the library: joint 3's compliance varies with its own angle",
    "growth": "outside the library: thermal growth of the arm scaling its position",
    "warmup": "outside the library: the joints' compliance growing over the session",
    "sensor_level": "outside the library: a force sensor's gain changing with the load's level",
    "sensor_offset": "outside the library: a zero offset of a flange force sensor's reading",
    "sensor_offset_base": "outside the library: a zero offset of the force reading fixed in the "
                          "base frame",
}


def parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def read_csv(path):
    comments, header, rows = [], None, []
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                comments.append(line)
            elif header is None:
                header = line.strip().split(",")
            elif line.strip():
                rows.append(line.strip().split(","))
    return comments, header, rows


DISPLACEMENT_UNITS = {"m": 1.0, "mm": 1e3, "um": 1e6}


def displacement_columns(header, path):
    """(column index, scale from metres) of dx, dy, dz in any unit the format allows."""
    out = []
    for axis in ("dx", "dy", "dz"):
        found = [(i, DISPLACEMENT_UNITS[h.split("_", 1)[1]]) for i, h in enumerate(header)
                 if h.split("_", 1)[0] == axis and h.split("_", 1)[-1] in DISPLACEMENT_UNITS]
        if len(found) != 1:
            raise SystemExit(f"outside_probes: {path}: no {axis} column in m, mm or um")
        out.append(found[0])
    return out


def controls(data_dir, sets, seeds, robot):
    """Each control (type `none`) of the directory's index in the comma-separated `sets` and
    the `seeds` text: (set, seed, folder, its CSV files by name as read_csv gives them, the
    same as stiff Datasets in SI units whatever the file's, its truth.json)."""
    import stiff

    with open(os.path.join(data_dir, "index.json")) as f:
        index = json.load(f)
    sets, seeds = sets.split(","), parse_seeds(seeds)
    for e in index:
        s, name = e["path"].split("/")
        seed = int(name.rsplit("_", 1)[1])
        if e["type"] != "none" or s not in sets or seed not in seeds:
            continue
        src = os.path.join(data_dir, e["path"])
        files = {fn: read_csv(os.path.join(src, fn)) for fn in ("calib.csv", "valid.csv")}
        data = {fn: stiff.Dataset.read(os.path.join(src, fn), robot) for fn in files}
        with open(os.path.join(src, "truth.json")) as f:
            truth = json.load(f)
        yield s, seed, src, files, data, truth


def probe_arguments(doc, kinds, size, size_help):
    """The command line both probe scripts take."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--data", required=True, help="scenario directory with index.json")
    ap.add_argument("--out", required=True, help="directory to write (replaced)")
    ap.add_argument("--sets", default="base,sigma", help="sets whose controls are used")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--kinds", default=",".join(kinds))
    ap.add_argument("--size", type=float, default=size, help=size_help)
    ap.add_argument("--robot", default="rokae")
    return ap


def prepare(out, kinds, known, names, who):
    """False, with a message naming it, when a kind is not known; else the output directory
    emptied (nothing is removed before every kind is known)."""
    for k in kinds:
        if not known(k):
            print(f"{who}: unknown kind {k!r} (known: {', '.join(names)})", file=sys.stderr)
            return False
    if os.path.exists(out):
        shutil.rmtree(out)
    return True


def write_index(out, entries, who):
    with open(os.path.join(out, "index.json"), "w") as f:
        json.dump(entries, f, indent=1)
    print(f"{who}: {len(entries)} scenarios in {out}")


def write_scenario(src, dst, files, add, forces=None, times=None):
    """Copy the CSV files of `src` (read_csv's triples, by name) to `dst` with the displacements
    moved by add[name] (N x 3, metres; any unit of the file), when given the force columns
    replaced by forces[name] (N x 3, newtons, written to 0.01 N as the development data are) and
    a `t_s` column of times[name] (N, seconds) appended."""
    os.makedirs(dst)
    for fn, (comments, header, rows) in files.items():
        cols = displacement_columns(header, os.path.join(src, fn))
        fcols = [header.index(h) for h in ("fx_N", "fy_N", "fz_N")] if forces else []
        with open(os.path.join(dst, fn), "w") as f:
            f.writelines(comments)
            f.write(",".join(header + (["t_s"] if times else [])) + "\n")
            for i, (r, d) in enumerate(zip(rows, add[fn])):
                r = list(r)
                for k, (c, unit) in enumerate(cols):
                    r[c] = repr(float(float(r[c]) + unit * d[k]))
                for k, c in enumerate(fcols):
                    r[c] = f"{forces[fn][i, k]:.2f}"
                if times:
                    r.append(f"{times[fn][i]:.1f}")
                f.write(",".join(r) + "\n")


def load_torques(robot, q, f):
    """(the linear Jacobians N x 3 x n at the measured point, the joint torques N x n of the
    forces f applied there)."""
    jv = robot.jacobian(q)[:, :3, :]
    return jv, np.einsum("nij,ni->nj", jv, f)


def joint_deflection(robot, q, f, compliance):
    """(N, 3): the measured point's displacement under f through the joint compliances."""
    jv, tau = load_torques(robot, q, f)
    return np.einsum("nij,nj->ni", jv, tau * compliance)


def rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def angle_pair(kind):
    """(j, k), 0-based, of a kind `k<j>q<k>`, else None."""
    m = re.fullmatch(r"k([1-9])q([1-9])", kind)
    return (int(m.group(1)) - 1, int(m.group(2)) - 1) if m else None


def make_effect(kind, rng, robot, compliance):
    """(displacement function of (q [rad], F [N], session rows) -> N x 3 [m], parameters)."""
    if kind == "base_shift":
        r = rotation(rng)
        cb = r @ np.diag(rng.uniform(0.8, 2.5, 3)) @ r.T * 1e-6
        return (lambda q, f, n: f @ cb.T), {"C_b_m_per_N": cb.tolist()}
    if kind == "angle_joint":
        phi = rng.uniform(0, 2 * np.pi)

        def angle_joint(q, f, n):
            jv, tau = load_torques(robot, q, f)
            return jv[:, :, 2] * (np.cos(2 * q[:, 2] + phi) * tau[:, 2])[:, None]
        return angle_joint, {"phase_rad": phi}
    if angle_pair(kind):
        j, k = angle_pair(kind)
        phi = rng.uniform(0, 2 * np.pi)

        def joint_by_angle(q, f, n):
            jv, tau = load_torques(robot, q, f)
            return jv[:, :, j] * (np.cos(q[:, k] + phi) * tau[:, j])[:, None]
        return joint_by_angle, {"phase_rad": phi}
    if kind == "warmup":
        def warmup(q, f, n):
            return joint_deflection(robot, q, f, compliance) * (np.arange(n) / n)[:, None]
        return warmup, {}
    if kind == "growth":
        return (lambda q, f, n: robot.tool_pose(q)[:, :3, 3] * n), {"per_row_of_session": True}
    if kind == "sensor_level":
        params = {"sign": float(rng.choice([-1.0, 1.0]))}  # a gain rising or falling

        def sensor_level(q, f, n):
            level = np.linalg.norm(f, axis=1)
            # One reference for both files: the calibration's mean level (it comes first).
            ref = params.setdefault("reference_level_N", float(level.mean()))
            gain = params["sign"] * (level - ref) / ref
            return -joint_deflection(robot, q, f * gain[:, None], compliance)
        return sensor_level, params
    if kind in ("sensor_offset", "sensor_offset_base"):
        b = rng.normal(size=3)
        b /= np.linalg.norm(b)
        flange = kind == "sensor_offset"

        def offset(q, f, n):
            if flange:
                fb = np.einsum("nij,j->ni", robot.tool_pose(q)[:, :3, :3], b)
            else:
                fb = np.tile(b, (len(q), 1))
            return -joint_deflection(robot, q, fb, compliance)
        return offset, {"direction": b.tolist(), "frame": "flange" if flange else "base"}
    raise ValueError(kind)


def main() -> int:
    ap = probe_arguments(__doc__, KINDS, 55.0, "effect RMS per axis [um]")
    a = ap.parse_args()
    import stiff

    robot = stiff.Robot(a.robot)
    kinds = a.kinds.split(",")
    if not prepare(a.out, kinds, lambda k: k in KINDS or angle_pair(k), KINDS, "outside_probes"):
        return 2
    out_index = []
    for s, seed, src, files, data, truth0 in controls(a.data, a.sets, a.seeds, robot):
        arrays = {fn: (d.q, d.force, len(d)) for fn, d in data.items()}
        compliance = 1.0 / np.asarray(stiff.identify(robot, data["calib.csv"]).stiffness)
        for kind in kinds:
            rng = np.random.default_rng(
                [seed, KINDS.index(kind)] if kind in KINDS else [seed] + [ord(c) for c in kind])
            fn_effect, params = make_effect(kind, rng, robot, compliance)
            add = {fn: fn_effect(*arrays[fn]) for fn in files}
            scale = a.size * 1e-6 / np.sqrt(np.mean(add["calib.csv"] ** 2))
            # The parameters as applied (the size sets the scale of the drawn ones).
            if kind == "base_shift":
                params["C_b_m_per_N"] = (np.array(params["C_b_m_per_N"]) * scale).tolist()
            elif kind == "angle_joint" or angle_pair(kind):
                params["amplitude_rad_per_Nm"] = scale
            elif kind == "growth":
                params["strain_per_row"] = scale
            elif kind == "warmup":
                params["compliance_gain_over_session"] = scale
            elif kind == "sensor_level":
                params["gain_per_relative_level"] = scale
            elif kind in ("sensor_offset", "sensor_offset_base"):
                params["offset_N"] = scale
            dst = os.path.join(a.out, s, f"{kind}_{seed:02d}")
            write_scenario(src, dst, files, {fn: add[fn] * scale for fn in files})
            what = DESCRIPTION.get(kind) or (
                f"outside the library: joint {kind[1]}'s compliance varies with joint "
                f"{kind[3]}'s angle")
            truth = dict(truth0, type=kind, description=what,
                         expected={"verdict": "unexplained"}, effect_parameters=params,
                         effect_scale_factor=scale,
                         effect_rms_calib_um=float(1e6 * scale *
                                                   np.sqrt(np.mean(add["calib.csv"] ** 2))))
            with open(os.path.join(dst, "truth.json"), "w") as f:
                json.dump(truth, f, indent=1)
            out_index.append({"path": f"{s}/{kind}_{seed:02d}", "type": kind,
                              "expected": {"verdict": "unexplained"}})
    write_index(a.out, out_index, "outside_probes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
