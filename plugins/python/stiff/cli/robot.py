"""stiff robot: what stiff reads from a robot file (chain, limits, frames, tool) and the YAML
form of it."""
from __future__ import annotations

import math

import numpy as np

from . import UserError
from .common import Formatter, add_robot, atomic_write_text, load_robot, table

EXAMPLE = """example:
  stiff robot show --robot ur5
  stiff robot show --robot ur5 --tip wrist_3_link --measured-point 0,0,120 --yaml ur5.yaml
  stiff identify --robot ur5 --data examples/real/ur5/ur5_grid.csv --model registration+tool+joint_offset+kinematic -o ur5.json
  stiff robot show --robot ur5 --fit ur5.json --yaml ur5_calibrated.yaml
  stiff robot show --robot ur5 --fit ur5.json --urdf ur5_calibrated.urdf

For a URDF the chain runs from --base (default base_link, else the root link) to --tip
(default tool0 or flange when present, else the only chain end); `show` lists the chain ends
it did not use. --yaml writes the chain as stiff uses it in the YAML robot format. With --fit
(an absolute calibration of this robot) it shows and writes the calibrated robot: the fit's
joint offsets, kinematic errors and tool built into the chain, for tools that take a robot
description; what a description cannot hold (compliance, harmonics) is listed. --urdf writes
the chain as a URDF (links base_link, link_1..link_n, tool0 = flange, tcp = measured point);
with --fit, the fit's registration places the base in a `world` link, the instrument's frame
(--session names the placement when the fit has several)."""


def register(sub):
    p = sub.add_parser("robot", help="show what stiff reads from a robot file; convert to YAML",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    rs = p.add_subparsers(dest="robot_command", metavar="<action>", required=True)
    s = rs.add_parser("show", help="print the chain, joint limits, frames and tool",
                      description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(s)
    s.add_argument("--yaml", metavar="FILE", help="also write the robot in the YAML format")
    s.add_argument("--urdf", metavar="FILE", help="also write the robot as a URDF")
    s.add_argument("--session", metavar="S",
                   help="with --fit and --urdf: the session whose registration places the base "
                        "in the `world` link (default: the fit's only session)")
    s.add_argument("--fit", metavar="FIT",
                   help="a calibration of this robot: show and write the calibrated robot")
    s.set_defaults(func=run_show)


def _mm(v) -> str:
    return ", ".join(f"{1e3 * x:.6g}" for x in v)


def run_show(args):
    robot = load_robot(args)
    fit = None
    if args.session and not (args.fit and args.urdf):
        raise UserError("--session needs --fit and --urdf (it places the calibrated robot "
                        "in that session's instrument frame)")
    if args.fit:
        from .. import api
        fit = api.Fit.read(args.fit)
        robot = robot.calibrated(fit)
    n = robot.dof
    lo, hi = robot.limits
    q0 = np.zeros(n)
    pose = robot.tool_pose(q0)
    jac = robot.jacobian(q0)
    lines = [f"robot: {robot.name} ({robot.path}{', ' + args.fit if args.fit else ''}), "
             f"{n} joints"]
    lines += [f"  {note}" for note in robot.notes]
    rows = []
    for j, name in enumerate(robot.joint_names):
        axis = np.round(jac[3:, j], 9) + 0.0  # no -0.000 from rounding noise
        rows.append([j + 1, name, f"{axis[0]:+.3f} {axis[1]:+.3f} {axis[2]:+.3f}",
                     f"{math.degrees(lo[j]):.1f}", f"{math.degrees(hi[j]):.1f}"])
    lines += ["", table(["#", "joint", "axis at q = 0 (base)", "lower [deg]", "upper [deg]"],
                        rows, ["<", "<", "<", ">", ">"]), ""]
    lines.append(f"measured point (SMR), tip frame [mm]: {_mm(robot.measured_point)}")
    lines.append(f"load point, tip frame [mm]:           {_mm(robot.load_point)}")
    lines.append(f"tool: {robot.tool_mass:.6g} kg, centre of mass (tip frame) [mm]: "
                 f"{_mm(robot.tool_com)}")
    rot = pose[:3, :3]
    lines.append(f"measured point at q = 0, base frame [mm]: {_mm(pose[:3, 3])}")
    lines.append("tip orientation at q = 0 (rows of R): " +
                 "; ".join(" ".join(f"{x:+.4f}" for x in r) for r in np.round(rot, 9) + 0.0))
    print("\n".join(lines))
    if args.yaml:
        atomic_write_text(args.yaml, robot.to_yaml())
        print(f"wrote {args.yaml} (YAML robot format, SI units)")
    if args.urdf:
        world, placed = None, ""
        if fit is not None and "registration" in fit.model:
            from ..errors import InvalidArgumentError
            try:
                world = fit.registration(args.session)
                placed = "; the base placed in the `world` link by the fit's registration"
            except InvalidArgumentError as e:
                if args.session:
                    raise
                placed = f"; no `world` link: {str(e).split(': ', 1)[-1]} with --session"
        atomic_write_text(args.urdf, robot.to_urdf(world))
        print(f"wrote {args.urdf} (URDF, m and rad{placed})")
    return 0
