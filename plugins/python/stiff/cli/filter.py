"""stiff filter: a vendor robot program in, the same program with compensated targets out.

Reads a KUKA KRL (.src + .dat), ABB RAPID (.mod) or Fanuc LS (.ls) program, compensates every
motion target for the deflection under the wrench of its motion (constant process force,
per-target force file, tool weight, Kienzle milling model) and writes the program into the
output directory with only the target numbers (and, if needed, configuration flags) changed.
Prints the per-target report: predicted deflection of the nominal program, correction,
predicted residual of the written program, flags."""
from __future__ import annotations

import csv
import io
import json

import numpy as np

from .. import api
from ..olp import (MATERIALS, FilterOptions, JointMap, KienzleMaterial, MillingCut, ToolLoad,
                   WrenchSpec, read_program, filter_program)
from ..olp import frames as fr
from . import UserError
from .common import Formatter, add_robot, atomic_write_text, robot_path, table

EXAMPLE = """worked example (docs/olp.md):
  stiff simulate --robot rokae --stiffness 50914,16382,31311,7791.1,5613.6,4000 --count 40 \\
      -o data.csv
  stiff identify --robot rokae --data data.csv -o fit.json
  stiff filter --robot rokae --fit fit.json examples/programs/kuka/slot.src --tool-weight \\
      --material C45 --cut 10,2,0.05,5,2 -o filtered --report filtered/report.csv

Frames the program names by number live in the controller: --frame N=..., --tool N=...
in the program's own convention (KRL x,y,z,a,b,c; Fanuc x,y,z,w,p,r; JBI x,y,z,rx,ry,rz)
[mm, deg];
--load N=mass,cx,cy,cz [kg, mm] for KRL LOAD_DATA[N]."""


def _floats(text: str, n, what: str) -> list:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise UserError(f"{what}: '{text}' is not a comma-separated list of numbers")
    if (isinstance(n, int) and len(v) != n) or (isinstance(n, tuple) and len(v) not in n):
        raise UserError(f"{what}: expected {n} values, got {len(v)}")
    return v


def _numbered(items, n, what, convert) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"{what} '{item}': expected N=values")
        k, v = item.split("=", 1)
        try:
            key = int(k)
        except ValueError:
            raise UserError(f"{what} '{item}': N must be an integer")
        out[key] = convert(_floats(v, n, what))
    return out


def register(sub):
    p = sub.add_parser("filter", help="compensate the targets of a KUKA, ABB, Fanuc or Yaskawa "
                       "program",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("program", help="program file: .src (KRL, its .dat beside it), .mod, .ls, "
                   ".jbi")
    p.add_argument("--fit", "-f", required=True, help="fit JSON of the robot")
    p.add_argument("--output", "-o", required=True,
                   help="output directory (the program is written there under its own name)")
    p.add_argument("--report", action="append", default=[],
                   help="per-target report: .csv or .json (repeatable)")
    p.add_argument("--force", help="constant process force on linear/circular moves in the "
                   "program's reference frame: fx,fy,fz[,mx,my,mz] [N, N*m]")
    p.add_argument("--force-file", help="CSV target,fx_N,fy_N,fz_N[,mx_Nm,my_Nm,mz_Nm] "
                   "(target = report number, from 1)")
    p.add_argument("--tool-weight", action="store_true",
                   help="add the weight of the program's tool load (RAPID tooldata, KRL $LOAD)")
    p.add_argument("--tool-load", help="tool load instead of the program's: mass,cx,cy,cz "
                   "[kg, mm in the flange frame]")
    p.add_argument("--material", help="Kienzle constants by name: " + ", ".join(MATERIALS))
    p.add_argument("--kc", help="Kienzle constants kc1.1,mc [N/mm^2, -] (instead of --material)")
    p.add_argument("--cut", help="milling cut D,z,fz,ae,ap [mm, teeth, mm, mm, mm]")
    p.add_argument("--spindle-rpm", type=float,
                   help="spindle speed [1/min]: the feed per tooth of each motion follows from "
                   "its programmed speed, f_z = v / (n z), instead of the fz of --cut")
    p.add_argument("--up-milling", action="store_true", help="up (conventional) milling; "
                   "default down (climb) milling")
    p.add_argument("--radial-ratio", type=float, default=0.3, help="F_r / F_t (default 0.3)")
    p.add_argument("--axial-ratio", type=float, default=0.0, help="F_a / F_t (default 0)")
    p.add_argument("--frame", action="append", help="controller base/user frame N=values")
    p.add_argument("--tool", action="append", help="controller tool frame N=values")
    p.add_argument("--load", action="append", help="KRL LOAD_DATA[N]=mass,cx,cy,cz [kg, mm]")
    p.add_argument("--joint-map", help="controller joints from the robot file's: "
                   "sign:offset_deg per joint, e.g. -1:0,1:-90,1:90,-1:0,1:0,-1:0")
    p.add_argument("--decimals", type=int, default=6,
                   help="minimum decimals of written mm and deg (quaternions +3; default 6)")
    p.add_argument("--tool-rotation", type=float, metavar="LIMIT_DEG",
                   help="stiffness-aware rotation about the tool axis of every process path, "
                   "within +-LIMIT_DEG (report column tool_rotation_deg)")
    p.add_argument("--tool-rotation-step", type=float, default=10.0,
                   help="largest rotation change between consecutive targets [deg] (default 10)")
    p.add_argument("--allow-config-change", action="store_true",
                   help="write targets whose configuration the compensation changes (flagged)")
    p.set_defaults(func=run)


def run(args):
    ext = args.program.lower().rsplit(".", 1)[-1]
    conv = fr.fanuc_to_pose if ext in ("ls", "jbi") else fr.kuka_to_pose
    frames = _numbered(args.frame, 6, "--frame", lambda v: conv(*v))
    tools = _numbered(args.tool, 6, "--tool", lambda v: conv(*v))
    loads = _numbered(args.load, 4, "--load",
                      lambda v: ToolLoad(v[0], np.array(v[1:]) * fr.MM))
    program = read_program(args.program, frames=frames, tools=tools, loads=loads)
    spec = WrenchSpec(tool_weight=args.tool_weight, force_file=args.force_file)
    if args.force:
        spec.force = _floats(args.force, (3, 6), "--force")
    if args.tool_load:
        v = _floats(args.tool_load, 4, "--tool-load")
        spec.tool_load = ToolLoad(v[0], np.array(v[1:]) * fr.MM)
        spec.tool_weight = True
    if args.material or args.kc or args.cut:
        if not args.cut or not (args.material or args.kc):
            raise UserError("the milling model needs --cut and --material (or --kc)")
        if args.material:
            if args.material not in MATERIALS:
                raise UserError(f"--material {args.material}: known: {', '.join(MATERIALS)}")
            mat = MATERIALS[args.material]
        else:
            k = _floats(args.kc, 2, "--kc")
            mat = KienzleMaterial(k[0], k[1], "--kc")
        d, z, fz, ae, ap = _floats(args.cut, 5, "--cut")
        cut = MillingCut(d, int(z), fz, ae, ap, not args.up_milling, args.radial_ratio,
                         args.axial_ratio)
        cut.check()
        spec.milling = (mat, cut)
        if args.spindle_rpm is not None:
            if not args.spindle_rpm > 0:
                raise UserError("--spindle-rpm must be positive")
            spec.spindle_rpm = args.spindle_rpm
    opts = FilterOptions(min_decimals=args.decimals, allow_config_change=args.allow_config_change,
                         tool_rotation_limit_deg=args.tool_rotation,
                         tool_rotation_max_step_deg=args.tool_rotation_step)
    if args.joint_map:
        opts.joint_map = JointMap.parse(args.joint_map)
    robot = api.Robot(robot_path(args.robot))
    model = api.Model(robot, api.Fit.read(args.fit))
    result = filter_program(program, model, spec, opts)
    written = result.write(args.output)
    rows = result.table()
    rot = args.tool_rotation is not None
    print(table(["#", "line", "name", "motion", "F [N]", "deflection [um]", "correction [um]",
                 "residual [um]"] + (["rot [deg]", "unrotated [um]"] if rot else []) + ["flags"],
                [[r["target"], r["line"], r["name"], r["motion"], f"{r['force_N']:.1f}",
                  f"{r['deflection_um']:.1f}", f"{r['correction_um']:.1f}",
                  f"{r['residual_um']:.3g}"] +
                 ([f"{r['tool_rotation_deg']:.0f}", f"{r['deflection_unrotated_um']:.1f}"]
                  if rot else []) + [r["flags"]] for r in rows]))
    s = result.summary()
    print(f"{program.fmt.name}: {s['targets']} targets, max predicted deflection "
          f"{s['max_deflection_um']:.1f} um, max residual after filtering "
          f"{s['max_residual_um']:.3g} um; wrote {', '.join(written)}")
    for rep in args.report:
        if rep.lower().endswith(".json"):
            atomic_write_text(rep, json.dumps({"program": args.program, "summary": s,
                                               "targets": rows}, indent=1))
        elif rep.lower().endswith(".csv"):
            buf = io.StringIO()
            w = csv.DictWriter(buf, fieldnames=list(rows[0].keys()) if rows else ["target"])
            w.writeheader()
            w.writerows(rows)
            atomic_write_text(rep, buf.getvalue())
        else:
            raise UserError(f"--report {rep}: use .csv or .json")
    return 0
