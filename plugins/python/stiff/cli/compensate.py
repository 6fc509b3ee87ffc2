"""stiff compensate: joint targets that make the loaded tool follow a machining path.

Reads a path (CSV of tool poses or G-code), solves the inverse kinematics with the branch kept,
and finds q_cmd with FK(q_cmd) + d(q_cmd, W) = nominal pose (6-D) under the process wrench W.
Writes the compensated joint path and the equivalent Cartesian targets FK(q_cmd) that an
offline-programming tool would post-process. With --truth (a virtual robot) it reports the
deviation of the loaded tool before and after compensation for every fit given."""
from __future__ import annotations

import json
import math
import sys

import numpy as np

from .. import api
from .. import compensate as cp
from . import UserError
from .common import Formatter, add_robot, atomic_write_text, fmt, robot_path, table

EXAMPLE = """worked example (virtual rokae arm with reducer backlash):
  stiff simulate --robot rokae --truth examples/truths/rokae_backlash.yaml -o data.csv
  stiff identify --robot rokae --data data.csv -o joint.json
  stiff identify --robot rokae --data data.csv --model joint+backlash -o full.json
  stiff compensate --robot rokae --fit joint.json --compare-fit full.json \\
      --path examples/paths/rokae_contour.csv --truth examples/truths/rokae_backlash.yaml \\
      -o compensated.csv --report deviation.png --report deviation.json

  G-code on a workpiece frame (x, y, z [mm], rx, ry, rz [deg] in the base frame), a constant
  process force and the tool pointing down:
  stiff compensate --robot rokae --fit joint.json --path examples/paths/pocket.nc \\
      --frame 370,-40,-150,0,0,0 --wrench 0,0,-100 --segment 1 -o pocket_comp.csv

Path CSV columns: x_mm|x_m, y_, z_; orientation rx_deg, ry_deg, rz_deg (fixed-axis XYZ) or qw,
qx, qy, qz, or none (tool pointing down / --tool-rpy); optional fx_N..fz_N, mx_Nm..mz_Nm per
point (in the path's frame). G-code: G0/G1 X Y Z F, G90/G91, G20/G21, comments; no arcs.
Output (SI): nominal pose, wrench, q<j>_rad (nominal IK), qcmd<j>_rad (compensated), the
compensated target x_cmd_m .. rz_cmd_rad = FK(q_cmd), and the point status (0 = ok; bits
1 singular, 2 unreachable, 4 branch change / wrist flip, 8 joint jump, 16 not converged)."""


def register(sub):
    p = sub.add_parser("compensate", help="compensate the deflection along a machining path",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--fit", "-f", action="append", required=True,
                   help="fit JSON; the first one is compensated into the output, repeat to "
                   "compare more fits in the report")
    p.add_argument("--compare-fit", action="append", default=[],
                   help="another fit to compare in the report (e.g. with the missing effect)")
    p.add_argument("--path", "-p", required=True, help="path CSV or G-code file")
    p.add_argument("--wrench", "-w",
                   help="constant wrench at the load point, base frame: fx,fy,fz[,mx,my,mz] "
                   "[N, N*m]; overrides wrench columns of the path")
    p.add_argument("--frame", help="workpiece frame in the base frame: x,y,z,rx,ry,rz "
                   "[mm, deg]; the path's poses are given in it (default: base frame)")
    p.add_argument("--tool-rpy", help="tool orientation rx,ry,rz [deg] in the workpiece frame "
                   "for G-code and CSV without orientation (default 180,0,0: pointing down)")
    p.add_argument("--segment", type=float, default=0.0,
                   help="split G1 moves into pieces of at most this length [mm] (default: end "
                   "points only)")
    p.add_argument("--q-start", help="joint positions [deg] the path starts from (picks the "
                   "IK branch; default 0 or the middle of the limits)")
    p.add_argument("--truth", help="truth YAML of a virtual robot: report the deviation of the "
                   "loaded tool before and after compensation")
    p.add_argument("-o", "--output", required=True, help="compensated path CSV to write")
    p.add_argument("--report", action="append", default=[],
                   help="deviation report to write: .png (plot) or .json; may repeat")
    p.add_argument("--progress", action=argparse_bool(), default=None,
                   help="show a progress bar (default: on a terminal for long paths)")
    p.set_defaults(func=run)


def argparse_bool():
    import argparse

    return argparse.BooleanOptionalAction


def _floats(text: str, name: str, counts) -> list[float]:
    try:
        v = [float(s) for s in text.split(",")]
    except ValueError:
        raise UserError(f"{name} must be comma-separated numbers, got '{text}'") from None
    if len(v) not in counts:
        raise UserError(f"{name} needs {' or '.join(map(str, counts))} values, got {len(v)}")
    if not all(math.isfinite(x) for x in v):
        raise UserError(f"{name} has a non-finite value")
    return v


class _Progress:
    def __init__(self, enabled: bool):
        self.enabled = enabled

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        width = 30
        k = int(width * done / max(total, 1))
        sys.stderr.write(f"\rcompensating [{'#' * k}{'.' * (width - k)}] {done}/{total} points")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _stats(dev: np.ndarray) -> dict:
    d = np.linalg.norm(dev[:, :3], axis=1)
    r = np.linalg.norm(dev[:, 3:], axis=1)
    return {"max_um": float(d.max() * 1e6), "rms_um": float(np.sqrt(np.mean(d ** 2)) * 1e6),
            "max_rot_urad": float(r.max() * 1e6)}


def run(args):
    for out in args.report:
        if not str(out).lower().endswith((".png", ".json")):
            raise UserError(f"--report {out}: use a .png or .json file name")
    robot = api.Robot(robot_path(args.robot))
    fit_paths = list(args.fit) + list(args.compare_fit)
    fits = [api.Fit.read(f) for f in fit_paths]
    models = [api.Model(robot, f) for f in fits]
    frame = None
    if args.frame:
        f = _floats(args.frame, "--frame", (6,))
        frame = [f[0] * 1e-3, f[1] * 1e-3, f[2] * 1e-3] + [math.radians(a) for a in f[3:]]
    tool = None
    if args.tool_rpy:
        tool = [math.radians(a) for a in _floats(args.tool_rpy, "--tool-rpy", (3,))]
    if not (args.segment >= 0):
        raise UserError("--segment must be >= 0")
    path = cp.read_path(args.path, frame=frame, tool_rpy=tool, segment_m=args.segment * 1e-3)
    n_pts = len(path)
    if args.wrench:
        w = _floats(args.wrench, "--wrench", (3, 6))
        if path.wrench is not None:
            print(f"note: --wrench overrides the wrench columns of {args.path}")
        wrench = np.repeat(np.array([w + [0.0] * (6 - len(w))]), n_pts, axis=0)
    elif path.wrench is not None:
        wrench = path.wrench
    else:
        raise UserError(f"{args.path} has no wrench columns (fx_N, fy_N, fz_N): give --wrench "
                        "fx,fy,fz[,mx,my,mz]")
    q_start = None
    if args.q_start:
        q_start = [math.radians(a) for a in _floats(args.q_start, "--q-start", (robot.dof,))]

    show = args.progress if args.progress is not None else (sys.stderr.isatty() and n_pts > 20000)
    chunk = 5000 if (show or n_pts > 20000) else 0
    results = []
    for k, model in enumerate(models):
        prog = _Progress(show and k == 0)
        results.append(cp.compensate_path(model, path.poses, wrench, q_start, chunk=chunk,
                                          progress=prog, nominal=(k == 0), targets=(k == 0)))
    main = results[0]
    q_nom = main.q_nominal
    predicted = models[0].predict(q_nom, wrench)

    # Output CSV (SI).
    n = robot.dof
    head = ["i", "line", "x_m", "y_m", "z_m", "rx_rad", "ry_rad", "rz_rad",
            "fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm"]
    head += [f"q{j + 1}_rad" for j in range(n)] + [f"qcmd{j + 1}_rad" for j in range(n)]
    head += ["x_cmd_m", "y_cmd_m", "z_cmd_m", "rx_cmd_rad", "ry_cmd_rad", "rz_cmd_rad", "status"]
    nom = cp.xyz_rpy_from_pose(path.poses)
    cmd = cp.xyz_rpy_from_pose(main.pose_cmd)
    meta = [f"# robot: {robot.name}", f"# fit: {fit_paths[0]}",
            f"# model: {'+'.join(fits[0].model)}", f"# path: {args.path}",
            "# frame: base; wrench at the load point, base frame",
            f"# ik: {'analytic' if cp.ik_is_analytic(robot) else 'numerical'}"]
    lines = meta + [",".join(head)]
    for i in range(n_pts):
        vals = [str(i), str(int(path.lines[i]))]
        vals += [repr(float(v)) for v in nom[i]] + [repr(float(v)) for v in wrench[i]]
        vals += [repr(float(v)) for v in q_nom[i]] + [repr(float(v)) for v in main.q_cmd[i]]
        vals += [repr(float(v)) for v in cmd[i]] + [str(int(main.status[i]))]
        lines.append(",".join(vals))
    atomic_write_text(args.output, "\n".join(lines) + "\n")

    # Summary.
    pd = np.linalg.norm(predicted[:, :3], axis=1)
    print(f"{n_pts} points, IK {'analytic' if cp.ik_is_analytic(robot) else 'numerical'}; "
          f"predicted deflection (model '{'+'.join(fits[0].model)}'): max {pd.max() * 1e6:.1f} "
          f"um, mean {pd.mean() * 1e6:.1f} um")
    problems = main.problems()
    if problems:
        kinds = {}
        for i, text in problems:
            kinds.setdefault(text, []).append(i)
        for text, idx in kinds.items():
            shown = ", ".join(map(str, idx[:10])) + (" ..." if len(idx) > 10 else "")
            print(f"warning: {len(idx)} point(s) {text}: index {shown}")
    report = {"robot": robot.name, "path": str(args.path), "points": n_pts,
              "ik": "analytic" if cp.ik_is_analytic(robot) else "numerical",
              "predicted_deflection": {"max_um": float(pd.max() * 1e6),
                                       "rms_um": float(np.sqrt(np.mean(pd ** 2)) * 1e6)},
              "problems": [{"index": i, "line": int(path.lines[i]), "status": t}
                           for i, t in problems],
              "fits": [{"fit": str(f), "model": "+".join(ft.model)}
                       for f, ft in zip(fit_paths, fits)]}
    curves = {}
    if args.truth:
        before = cp.truth_deviation(robot, args.truth, q_nom, path.poses, wrench)
        report["truth"] = str(args.truth)
        report["uncompensated"] = _stats(before)
        curves["uncompensated"] = np.linalg.norm(before[:, :3], axis=1)
        rows = [["uncompensated", "-", fmt(report["uncompensated"]["max_um"], ".2f"),
                 fmt(report["uncompensated"]["rms_um"], ".2f"), "1"]]
        for f, ft, res, entry in zip(fit_paths, fits, results, report["fits"]):
            after = cp.truth_deviation(robot, args.truth, res.q_cmd, path.poses, wrench)
            s = _stats(after)
            entry["compensated"] = s
            entry["ratio"] = s["max_um"] / max(report["uncompensated"]["max_um"], 1e-300)
            label = f"compensated, {'+'.join(ft.model)}"
            curves[label if label not in curves else f"{label} ({f})"] = np.linalg.norm(
                after[:, :3], axis=1)
            rows.append([f, "+".join(ft.model), fmt(s["max_um"], ".3g"), fmt(s["rms_um"], ".3g"),
                         fmt(entry["ratio"], ".3g")])
        print(f"deviation of the loaded tool from the nominal path on the virtual robot "
              f"({args.truth}):")
        print(table(["", "model", "max [um]", "rms [um]", "max / uncompensated"], rows))
    else:
        curves[f"predicted deflection, {'+'.join(fits[0].model)}"] = pd
    for out in args.report:
        if str(out).lower().endswith(".json"):
            atomic_write_text(out, json.dumps(report, indent=2) + "\n")
        elif str(out).lower().endswith(".png"):
            cp.plot_deviation(path.poses[:, :3, 3], curves, out)
        else:
            raise UserError(f"--report {out}: use a .png or .json file name")
        print(f"wrote {out}")
    print(f"wrote {args.output}")
    return 0
