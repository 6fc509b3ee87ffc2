#!/usr/bin/env python3
"""Make diagnosis scenarios on other arms than the example, from the library's virtual robot.

The development scenarios are all of one arm. This script writes, for each robot named, a
directory that bench/diagnosis_score.py reads (`<out>/<robot>/index.json`, `base/<type>_<seed>/`
with calib.csv, valid.csv, truth.json), each scenario one effect of the library (or none) on
that arm, simulated by `stiff simulate` with the realistic noise (tracker 10 um + 5 ppm, force
1 % + 0.3 N, stated in the files). It checks that nothing in the diagnosis is tied to one arm's
size, masses or joint layout; the effects have the library's own forms, so this is a test of
generality over arms, not over forms (bench/form_probes.py is that).

Joint stiffness: a fixed shape per arm scaled so that the joint deflection is `--joint-um` RMS
per axis on random poses; each effect's parameters are drawn at random and scaled to
`--effect-um` RMS per axis on the calibration rows (an effect a pose set cannot see, such as a
wrist term where the measured point sits at the wrist centre, is drawn again).
`true_class_refit_valid_um` is the noise's own RMS on valid.csv (the noise-free simulation
subtracted), so a ratio of 1 means the model predicts new poses to the noise.

Usage:
  .venv/bin/python bench/arm_probes.py --out /tmp/arms --seeds 0-9
  .venv/bin/python bench/diagnosis_score.py --data /tmp/arms/ur10 --robot ur10 --sets base --seeds 0-9

Needs numpy and the `stiff` Python package (run it with .venv/bin/python).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from outside_probes import parse_seeds, prepare, write_index

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STIFF = [sys.executable, "-m", "stiff.cli"]  # the command line of this interpreter's package
NOISE = os.path.join(ROOT, "examples", "truths", "noise_realistic.yaml")
# Relative joint stiffness: large reducers at the shoulder, smaller at the wrist.
SHAPE = {"ur10": [3.0, 3.0, 1.5, 0.5, 0.5, 0.5], "puma560": [3.0, 2.0, 2.0, 0.6, 0.5, 0.4],
         "abb_irb120": [3.0, 2.0, 2.0, 0.6, 0.5, 0.4], "rokae": [5.1, 1.6, 3.1, 0.78, 0.56, 0.4]}
KINDS = ("none", "link", "gravity_compensator", "nonlinear_joint", "backlash", "coupling",
         "tracker_frame", "force_frame", "point_offset", "tool_compliance")
NEEDS_MASSES = ("nonlinear_joint", "backlash")


def simulate(robot, truth, count, seed, out, noisy):
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
        f.write(truth)
    try:
        cmd = STIFF + ["simulate", "--robot", robot, "--truth", f.name, "--count", str(count),
               "--seed", str(seed), "-o", out]
        cmd += ["--noise", NOISE] if noisy else ["--tracker-sigma-um", "0"]
        subprocess.run(cmd, check=True, capture_output=True, text=True)
    finally:
        os.remove(f.name)


def displacements(path):
    import stiff

    return stiff.Dataset.read(path).displacement


def truth_yaml(stiffness, effects):
    text = "stiffness_Nm_per_rad: [" + ", ".join(f"{k:.6g}" for k in stiffness) + "]\n"
    if effects:
        text += "effects:\n"
        for name, params in effects.items():
            text += f"  {name}:\n" + "".join(f"    {p}: {v:.6g}\n" for p, v in params.items())
    return text


def draw(kind, rng, link_params):
    """A random instance of the effect (parameters at an arbitrary scale)."""
    if kind == "link":
        return {"link": {str(rng.choice(link_params)): 1e-6}}
    if kind == "gravity_compensator":
        return {"gravity_compensator": {"alpha": rng.normal() * 1e-5, "beta": rng.normal() * 1e-5}}
    if kind == "nonlinear_joint":  # hardening or softening with the cube of the total torque
        return {"nonlinear_joint": {"h2": rng.choice([-1, 1]) * 1e-6, "h3": rng.choice([-1, 1]) * 1e-6}}
    if kind == "backlash":
        return {"backlash": {"b2": 1e-4, "b3": 1e-4}}
    if kind == "coupling":
        pair = str(rng.choice(["c23", "c24", "c35", "c45", "c13"]))
        return {"coupling": {pair: rng.choice([-1, 1]) * 1e-5}}
    if kind == "tracker_frame":
        return {"tracker_frame": dict(zip(("omega_x", "omega_y", "omega_z"), rng.normal(size=3) * 0.01))}
    if kind == "force_frame":  # a flange sensor's clocking, or a fixture's direction in the base
        if rng.random() < 0.5:
            return {"force_frame": {"omega_z": 0.05, "omega_x": 0.03 * rng.normal()}}
        return {"force_frame": dict(zip(("omega_base_x", "omega_base_y", "omega_base_z"),
                                        rng.normal(size=3) * 0.05))}
    if kind == "point_offset":  # the SMR and the load on one tool plate, off the flange centre
        m = rng.normal(size=3) * 0.03
        return {"point_offset": dict(zip(("meas_x", "meas_y", "meas_z", "load_x", "load_y",
                                          "load_z"), np.concatenate([m, m])))}
    if kind == "tool_compliance":
        a = rng.normal(size=(3, 3))
        s = a @ a.T * 1e-6
        return {"tool_compliance": {"s_xx": s[0, 0], "s_yy": s[1, 1], "s_zz": s[2, 2],
                                    "s_xy": s[0, 1], "s_xz": s[0, 2], "s_yz": s[1, 2]}}
    raise ValueError(kind)


def scaled(effects, factor):
    return {n: {p: v * factor for p, v in params.items()} for n, params in effects.items()}


def rms_um(a):
    return float(np.sqrt(np.mean(a ** 2)) * 1e6)


def make_arm(robot, kinds, seeds, out, joint_um, effect_um, tmp):
    info = json.loads(subprocess.run(STIFF + ["effects", "--json", "--robot", robot],
                                     check=True, capture_output=True, text=True).stdout)
    available = {e["name"]: e for e in info if "unavailable" not in e}
    link_params = [p["name"] for p in available["link"]["parameters"]]
    shape = np.array(SHAPE.get(robot, [3.0, 2.0, 2.0, 0.6, 0.5, 0.4]))
    simulate(robot, truth_yaml(1e4 * shape, {}), 60, 999, f"{tmp}/s.csv", False)
    stiffness = 1e4 * shape * rms_um(displacements(f"{tmp}/s.csv")) / joint_um
    index, bases = [], {}
    for kind in kinds:
        if kind != "none" and kind not in available:
            print(f"{robot}: {kind} skipped ({robot}'s file has no link masses)", file=sys.stderr)
            continue
        for seed in seeds:
            rng = np.random.default_rng([seed, KINDS.index(kind)])
            if seed not in bases:  # the calibration poses without an effect, one per seed
                simulate(robot, truth_yaml(stiffness, {}), 60, 100 + seed, f"{tmp}/b.csv", False)
                bases[seed] = displacements(f"{tmp}/b.csv")
            base = bases[seed]
            effects = {}
            for _ in range(20 if kind != "none" else 0):
                effects, size = draw(kind, rng, link_params), 0.0
                for _ in range(3):  # the nonlinear effects need a second look at their scale
                    simulate(robot, truth_yaml(stiffness, effects), 60, 100 + seed,
                             f"{tmp}/e.csv", False)
                    size = rms_um(displacements(f"{tmp}/e.csv") - base)
                    if size < 1e-3:
                        break
                    effects = scaled(effects, effect_um / size)
                if size >= 1e-3:
                    break
            truth = truth_yaml(stiffness, effects)
            folder = os.path.join(out, robot, "base", f"{kind}_{seed:02d}")
            os.makedirs(folder, exist_ok=True)
            simulate(robot, truth, 60, 100 + seed, f"{folder}/calib.csv", True)
            simulate(robot, truth, 40, 5000 + seed, f"{folder}/valid.csv", True)
            simulate(robot, truth, 40, 5000 + seed, f"{tmp}/v.csv", False)
            floor = rms_um(displacements(f"{folder}/valid.csv") - displacements(f"{tmp}/v.csv"))
            expected = ({"verdict": "adequate", "effects": []} if kind == "none"
                        else {"verdict": "missing_effect", "effects": [kind]})
            with open(f"{folder}/truth.json", "w") as f:
                json.dump({"type": kind, "robot": robot, "expected": expected, "truth_yaml": truth,
                           "true_class_refit_valid_um": {"axis_um": floor}}, f, indent=1)
            index.append({"path": f"base/{kind}_{seed:02d}", "type": kind, "expected": expected})
    write_index(os.path.join(out, robot), index, f"arm_probes ({robot})")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="directory to write (replaced; one folder per robot)")
    ap.add_argument("--robots", default="ur10,puma560,abb_irb120",
                    help="built-in names or robot files, comma-separated")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--joint-um", type=float, default=300.0,
                    help="joint deflection RMS per axis the stiffness is scaled to [um]")
    ap.add_argument("--effect-um", type=float, default=55.0, help="effect RMS per axis [um]")
    a = ap.parse_args()
    kinds = a.kinds.split(",")
    if not prepare(a.out, kinds, lambda k: k in KINDS, KINDS, "arm_probes"):
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        for robot in a.robots.split(","):
            make_arm(robot, kinds, parse_seeds(a.seeds), a.out, a.joint_um, a.effect_um, tmp)
    return 0


if __name__ == "__main__":
    sys.exit(main())
