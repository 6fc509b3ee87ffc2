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
from .common import (Formatter, add_robot, atomic_write_text, builtin_path, fmt, load_robot,
                     robot_path, table)

EXAMPLE = """worked example (virtual rokae arm with reducer backlash; built-in files by name):
  stiff simulate --robot rokae --truth rokae_backlash --count 60 -o data.csv
  stiff identify --robot rokae --data data.csv -o joint.json
  stiff identify --robot rokae --data data.csv --model joint+backlash -o full.json
  stiff compensate --robot rokae --fit joint.json --compare-fit full.json \\
      --path rokae_contour --truth rokae_backlash \\
      -o compensated.csv --report deviation.png --report deviation.json

  G-code on a workpiece frame (x, y, z [mm], rx, ry, rz [deg] in the base frame), a constant
  process force and the tool pointing down:
  stiff compensate --robot rokae --fit joint.json --path pocket.nc \\
      --frame 370,-40,-150,0,0,0 --wrench 0,0,-100 --segment 1 -o pocket_comp.csv

Path CSV columns: x_mm|x_m, y_, z_; orientation rx_deg, ry_deg, rz_deg (fixed-axis XYZ) or qw,
qx, qy, qz, or none (tool pointing down / --tool-rpy); optional fx_N..fz_N, mx_Nm..mz_Nm per
point (in the path's frame). G-code as CAM post-processors write it: G0/G1, G2/G3 arcs (I J K
or R) in G17/G18/G19, G90/G91, G20/G21, G43 H / G49, G28/G53 (not path points), comments,
N numbers, a byte-order mark; rotary axis words must be 0 (use --tool-rpy). No point is made
before X, Y and Z are all known. G0 moves carry no process force (rapid = 1).
Output (SI): nominal pose (rx..rz and quaternion qw..qz), wrench, q<j>_rad (nominal IK),
qcmd<j>_rad (compensated), the compensated target x_cmd_m .. rz_cmd_rad and qw_cmd .. qz_cmd =
FK(q_cmd), the commanded correction (dpos_um, drot_urad), rapid, and the point status (0 = ok;
bits 1 singular, 2 unreachable, 4 branch change / wrist flip, 8 joint jump, 16 not converged).
Unreachable or non-converged points make the command fail (exit code 3, nothing written)
unless --keep-going: their rows are then written with empty joint and target fields."""


def register(sub):
    p = sub.add_parser("compensate", help="compensate the deflection along a machining path",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--fit", "-f", action="append", required=True,
                   help="fit JSON; the first one is compensated into the output, repeat to "
                   "compare more fits in the report")
    p.add_argument("--compare-fit", action="append", default=[],
                   help="another fit to compare in the report (e.g. with the missing effect)")
    p.add_argument("--path", "-p", required=True,
                   help="path CSV or G-code file, or a built-in path (rokae_contour, pocket.nc)")
    p.add_argument("--wrench", "-w",
                   help="constant wrench at the load point, base frame: fx,fy,fz[,mx,my,mz] "
                   "[N, N*m]; overrides wrench columns of the path")
    p.add_argument("--frame", help="workpiece frame in the base frame: x,y,z,rx,ry,rz "
                   "[mm, deg]; the path's poses are given in it (default: base frame)")
    p.add_argument("--tool-rpy", help="tool orientation rx,ry,rz [deg] in the workpiece frame "
                   "for G-code and CSV without orientation (default 180,0,0: pointing down)")
    p.add_argument("--segment", type=float, default=None,
                   help="split G1 moves into pieces of at most this length [mm] (default: end "
                   "points only)")
    p.add_argument("--q-start", help="joint positions [deg] the path starts from (picks the "
                   "IK branch; default 0 or the middle of the limits)")
    p.add_argument("--truth", help="truth YAML of a virtual robot: report the deviation of the "
                   "loaded tool before and after compensation")
    p.add_argument("-o", "--output", required=True, help="compensated path CSV to write")
    p.add_argument("--report", action="append", default=[],
                   help="deviation report to write: .png (plot) or .json; may repeat")
    p.add_argument("--keep-going", action="store_true",
                   help="write the output even if points are unreachable or do not converge "
                   "(their rows carry no command, only the status)")
    p.add_argument("--orientation-tolerance-urad", type=float, default=100.0,
                   help="with --truth: fail when the compensated tool's orientation error "
                   "exceeds the uncompensated one by more than this [urad] (default 100)")
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
    robot = load_robot(args)
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
    args.path = builtin_path("paths", args.path)
    if args.truth:
        args.truth = builtin_path("truths", args.truth)
    path = cp.read_path(args.path, frame=frame, tool_rpy=tool, segment_m=None if args.segment is None else args.segment * 1e-3)
    if args.segment is None:  # recorded in the outputs as the value the library used
        args.segment = cp.path_defaults()["segment_m"] * 1e3
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

    # Rapid (G0) moves position the tool: no process force acts there.
    rapid = path.rapid if path.rapid is not None else np.zeros(n_pts, dtype=bool)
    wrench = np.where(rapid[:, None], 0.0, wrench)

    show = args.progress if args.progress is not None else (sys.stderr.isatty() and n_pts > 20000)
    chunk = 5000 if (show or n_pts > 20000) else 0
    results = []
    for k, model in enumerate(models):
        prog = _Progress(show and k == 0)
        results.append(cp.compensate_path(model, path.poses, wrench, q_start, chunk=chunk,
                                          progress=prog, nominal=(k == 0), targets=(k == 0)))
    main = results[0]
    q_nom = main.q_nominal
    failed = (main.status & (cp.POINT_UNREACHABLE | cp.POINT_NOT_CONVERGED)) != 0
    if failed.any():
        idx = np.flatnonzero(failed)
        first = "; ".join(f"row {i} (line {int(path.lines[i])}): {cp.status_text(main.status[i])}"
                          for i in idx[:3])
        more = f" and {len(idx) - 3} more" if len(idx) > 3 else ""
        msg = (f"{len(idx)} of {n_pts} points cannot be compensated: {first}{more}")
        if not args.keep_going:
            print(f"stiff compensate: error: {msg}; nothing written (--keep-going writes the "
                  "other rows and marks these)", file=sys.stderr)
            return 3
        print(f"warning: {msg}; their rows carry no command (--keep-going)", file=sys.stderr)
    predicted = models[0].predict(q_nom, wrench)
    corr_pos = np.linalg.norm(main.pose_cmd[:, :3, 3] - path.poses[:, :3, 3], axis=1)
    corr_rot = cp.rotation_angle_between(path.poses, main.pose_cmd)

    # Output CSV (SI).
    n = robot.dof
    head = ["i", "line", "x_m", "y_m", "z_m", "rx_rad", "ry_rad", "rz_rad", "qw", "qx", "qy", "qz",
            "fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm"]
    head += [f"q{j + 1}_rad" for j in range(n)] + [f"qcmd{j + 1}_rad" for j in range(n)]
    head += ["x_cmd_m", "y_cmd_m", "z_cmd_m", "rx_cmd_rad", "ry_cmd_rad", "rz_cmd_rad",
             "qw_cmd", "qx_cmd", "qy_cmd", "qz_cmd", "dpos_um", "drot_urad", "rapid", "status"]
    nom = np.hstack([cp.xyz_rpy_from_pose(path.poses), cp.quaternion_from_pose(path.poses)])
    cmd = np.hstack([cp.xyz_rpy_from_pose(main.pose_cmd), cp.quaternion_from_pose(main.pose_cmd)])
    mp, lp = robot.measured_point * 1e3, robot.load_point * 1e3
    meta = [f"# robot: {robot.name} ({robot.path})"]
    meta += [f"# robot {note}" for note in robot.notes]
    meta += [f"# measured point [mm, tip frame]: {mp[0]:.6g}, {mp[1]:.6g}, {mp[2]:.6g}; "
             f"load point: {lp[0]:.6g}, {lp[1]:.6g}, {lp[2]:.6g}; tool mass {robot.tool_mass:.6g} kg",
             f"# fit: {fit_paths[0]}", f"# model: {'+'.join(fits[0].model)}",
             f"# path: {args.path}",
             f"# workpiece frame [mm, deg]: {args.frame or '0,0,0,0,0,0 (base frame)'}",
             f"# tool orientation [deg]: {args.tool_rpy or ('from the path' if path_has_orientation(args.path) else '180,0,0 (pointing down)')}",
             f"# wrench: {('--wrench ' + args.wrench) if args.wrench else 'path columns'}"
             f" (G0 rows: none); segment: {args.segment:g} mm; q start [deg]: {args.q_start or 'default'}",
             "# poses and wrench in the base frame; wrench at the load point",
             f"# ik: {'analytic' if cp.ik_is_analytic(robot) else 'numerical'}"]
    lines = meta + [",".join(head)]
    for i in range(n_pts):
        vals = [str(i), str(int(path.lines[i]))]
        vals += [repr(float(v)) for v in nom[i]] + [repr(float(v)) for v in wrench[i]]
        if failed[i]:  # no made-up command: empty joint and target fields
            vals += [""] * (2 * n + 12)
        else:
            vals += [repr(float(v)) for v in q_nom[i]] + [repr(float(v)) for v in main.q_cmd[i]]
            vals += [repr(float(v)) for v in cmd[i]]
            vals += [f"{corr_pos[i] * 1e6:.4f}", f"{corr_rot[i] * 1e6:.4f}"]
        vals += [str(int(rapid[i])), str(int(main.status[i]))]
        lines.append(",".join(vals))
    csv_text = "\n".join(lines) + "\n"
    ok = ~failed

    # Summary.
    pd = np.linalg.norm(predicted[ok, :3], axis=1)
    pr = np.linalg.norm(predicted[ok, 3:], axis=1)
    print(f"{n_pts} points ({int(rapid.sum())} rapid), IK "
          f"{'analytic' if cp.ik_is_analytic(robot) else 'numerical'}; predicted deflection "
          f"(model '{'+'.join(fits[0].model)}'): max {np.max(pd, initial=0.0) * 1e6:.1f} um, mean "
          f"{pd.mean() * 1e6:.1f} um, orientation max {np.max(pr, initial=0.0) * 1e6:.1f} urad")
    print(f"commanded correction: position max {np.max(corr_pos[ok], initial=0.0) * 1e6:.1f} um, "
          f"orientation max {np.max(corr_rot[ok], initial=0.0) * 1e6:.1f} urad")
    absolute = [e for e in fits[0].model if "absolute" in api.describe_effect(e)["needs"]]
    if absolute:
        print(f"the fit calibrates the robot ({'+'.join(absolute)}): the command brings the "
              "calibrated tool point to the path under the calibrated geometry and the robot's "
              "weight as well; the deflection above is the process load's alone")
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
              "predicted_deflection": {"max_um": float(np.max(pd, initial=0.0) * 1e6),
                                       "rms_um": float(np.sqrt(np.mean(pd ** 2)) * 1e6),
                                       "max_rot_urad": float(np.max(pr, initial=0.0) * 1e6)},
              "correction": {"max_um": float(np.max(corr_pos[ok], initial=0.0) * 1e6),
                             "max_rot_urad": float(np.max(corr_rot[ok], initial=0.0) * 1e6)},
              "options": {"frame": args.frame, "tool_rpy": args.tool_rpy, "wrench": args.wrench,
                          "segment_mm": args.segment, "q_start_deg": args.q_start,
                          "base": getattr(args, "base", None), "tip": getattr(args, "tip", None),
                          "measured_point_mm": getattr(args, "measured_point", None),
                          "load_point_mm": getattr(args, "load_point", None),
                          "keep_going": args.keep_going},
              "rapid_points": int(rapid.sum()),
              "failed_points": [int(i) for i in np.flatnonzero(failed)],
              "problems": [{"index": i, "line": int(path.lines[i]), "status": t}
                           for i, t in problems],
              "fits": [{"fit": str(f), "model": "+".join(ft.model)}
                       for f, ft in zip(fit_paths, fits)]}
    curves = {}
    worse = []
    if args.truth:
        before = cp.truth_deviation(robot, args.truth, q_nom[ok], path.poses[ok], wrench[ok])
        report["truth"] = str(args.truth)
        report["uncompensated"] = _stats(before)
        curves["uncompensated"] = np.linalg.norm(before[:, :3], axis=1)
        u = report["uncompensated"]
        rows = [["uncompensated", "-", fmt(u["max_um"], ".2f"), fmt(u["rms_um"], ".2f"),
                 fmt(u["max_rot_urad"], ".4g"), "1"]]
        for f, ft, res, entry in zip(fit_paths, fits, results, report["fits"]):
            after = cp.truth_deviation(robot, args.truth, res.q_cmd[ok], path.poses[ok], wrench[ok])
            st = _stats(after)
            entry["compensated"] = st
            entry["ratio"] = st["max_um"] / max(u["max_um"], 1e-300)
            if st["max_rot_urad"] > u["max_rot_urad"] + args.orientation_tolerance_urad:
                worse.append(f"{f}: orientation error {st['max_rot_urad']:.4g} urad after "
                             f"compensation, {u['max_rot_urad']:.4g} urad before")
            label = f"compensated, {'+'.join(ft.model)}"
            curves[label if label not in curves else f"{label} ({f})"] = np.linalg.norm(
                after[:, :3], axis=1)
            rows.append([f, "+".join(ft.model), fmt(st["max_um"], ".3g"), fmt(st["rms_um"], ".3g"),
                         fmt(st["max_rot_urad"], ".4g"), fmt(entry["ratio"], ".3g")])
        print(f"deviation of the loaded tool from the nominal path on the virtual robot "
              f"({args.truth}):")
        print(table(["", "model", "max [um]", "rms [um]", "max rot [urad]",
                     "max / uncompensated"], rows))
    else:
        curves[f"predicted deflection, {'+'.join(fits[0].model)}"] = pd
    if worse and not args.keep_going:
        print("stiff compensate: error: the compensation worsens the tool orientation beyond "
              f"{args.orientation_tolerance_urad:g} urad (--orientation-tolerance-urad): " +
              "; ".join(worse) + "; nothing written (--keep-going writes it anyway)",
              file=sys.stderr)
        return 3
    for out in args.report:
        if str(out).lower().endswith(".json"):
            atomic_write_text(out, json.dumps(report, indent=2) + "\n")
        elif str(out).lower().endswith(".png"):
            cp.plot_deviation(path.poses[ok, :3, 3], curves, out)
        else:
            raise UserError(f"--report {out}: use a .png or .json file name")
        print(f"wrote {out}")
    atomic_write_text(args.output, csv_text)
    print(f"wrote {args.output}")
    if worse:
        print("warning: the compensation worsens the tool orientation: " + "; ".join(worse),
              file=sys.stderr)
    return 0


def path_has_orientation(path) -> bool:
    """True for a CSV path with orientation columns (rx_/qw), else the tool orientation option
    or its default applies."""
    if not str(path).lower().endswith(".csv"):
        return False
    try:
        with open(path, encoding="utf-8-sig") as f:
            for line in f:
                if line.strip() and not line.lstrip().startswith("#"):
                    cols = [c.strip().lower() for c in line.split(",")]
                    return any(c.startswith(("rx_", "qw")) for c in cols)
    except OSError:
        return False
    return False
