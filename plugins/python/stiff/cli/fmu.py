"""stiff fmu: export the identified deflection model as an FMU for co-simulation."""
from __future__ import annotations

from pathlib import Path

from .. import api
from ..fmu import export_fmu, fmu_defaults
from .._outputs import written
from .common import Formatter, add_robot, load_robot, robot_path

EXAMPLE = """example:
  stiff fmu export --robot rokae --fit fit.json -o arm.fmu            # FMI 2.0 (ME + CS)
  stiff fmu export --robot rokae --fit fit.json --fmi 3 -o arm3.fmu   # FMI 3.0
  stiff fmu export --robot rokae --fit fit.json --fmi 3 --array-inputs -o arm3a.fmu
  python -c "import fmpy; fmpy.dump('arm.fmu')"

Inputs q1..qn [rad] and the wrench fx, fy, fz [N], mx, my, mz [N*m] at the tool point (base
frame, or tool frame with the parameter wrench_frame = 1). Outputs the deflection dx, dy, dz
[m], rx, ry, rz [rad] (base frame), the loaded tool position and q_cmd1..n: the joint command
that puts the loaded tool where the unloaded program wanted it (docs/fmu.md)."""


def register(sub):
    p = sub.add_parser("fmu", help="export the model as an FMU (FMI 2.0/3.0)",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    fsub = p.add_subparsers(dest="fmu_command", metavar="<action>")
    e = fsub.add_parser("export", help="write an .fmu", description=__doc__, epilog=EXAMPLE,
                        formatter_class=Formatter)
    add_robot(e)
    e.add_argument("--fit", "-f", required=True, help="fit JSON from `stiff identify`")
    d = fmu_defaults()  # the library's (stiff_fmu_options_init); unset options stay None
    e.add_argument("--fmi", type=int, choices=[2, 3], help=f"FMI version (default {d['fmi_version']})")
    e.add_argument("--identifier",
                   help=f"model identifier (default {d['model_identifier']})")
    e.add_argument("--array-inputs", action="store_true",
                   help="FMI 3: inputs as the arrays q[n] and wrench[6] instead of the scalars "
                        "q1..qn, fx..mz (one set of inputs per FMU)")
    e.add_argument("-o", "--output", required=True, help=".fmu file to write")
    e.set_defaults(func=run)
    p.set_defaults(func=lambda args: p.print_help() or 2)


def run(args):
    robot = load_robot(args)
    fit = api.Fit.read(args.fit)
    path = export_fmu(robot, fit, args.output, fmi_version=args.fmi,
                      model_identifier=args.identifier, array_inputs=args.array_inputs or None)
    d = fmu_defaults()
    args.fmi = d["fmi_version"] if args.fmi is None else args.fmi
    args.identifier = d["model_identifier"] if args.identifier is None else args.identifier
    size = Path(written(path)).stat().st_size  # committed when the command ends
    inputs = "array inputs q, wrench" if args.array_inputs else "scalar inputs"
    print(f"wrote {path} (FMI {args.fmi}.0, model '{args.identifier}', {inputs}, "
          f"{len(fit.parameters)} tunable parameters, {size / 1e6:.1f} MB)")
    return 0
