"""stiff simulate: measurements from the virtual robot."""
from __future__ import annotations

from .. import api
from .common import Formatter, add_robot, robot_path

EXAMPLE = """example:
  stiff simulate --robot rokae --plan plan.csv --stiffness 50914,16382,31311,7791,5614,4000 \\
      --tracker-sigma-um 10 -o data.csv
  stiff simulate --robot rokae --truth truth.yaml --noise noise.yaml --count 60 -o data.csv

The truth file names the joint stiffness and any hidden effects (docs/formats.md); the noise
file the tracker sigma (constant + ppm), force and joint errors, outliers and the seed.
Without --plan, --count random valid poses with loads of 15-35 N per axis are used."""


def register(sub):
    p = sub.add_parser("simulate", help="simulate loaded measurements on the virtual robot",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--plan", help="plan or measurement CSV giving poses and loads")
    p.add_argument("--count", type=int, default=20, help="random poses when no --plan (default 20)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--truth", help="truth YAML (stiffness and hidden effects)")
    g.add_argument("--stiffness", help="true joint stiffness, comma-separated [N*m/rad]")
    p.add_argument("--noise", help="noise YAML (overrides the noise options below)")
    p.add_argument("--tracker-sigma-um", type=float, default=10.0, help="tracker sigma per axis [um] (default 10)")
    p.add_argument("--tracker-ppm", type=float, default=0.0, help="distance-proportional tracker error [ppm]")
    p.add_argument("--force-relative", type=float, default=0.0, help="relative force error (1 sigma)")
    p.add_argument("--force-absolute-n", type=float, default=0.0, help="absolute force error [N]")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.set_defaults(func=run)


def run(args):
    from . import UserError

    robot = api.Robot(robot_path(args.robot))
    design = api.Dataset.read(args.plan, robot) if args.plan else api.random_design(robot, args.count, args.seed)
    noise = dict(tracker_sigma_m=args.tracker_sigma_um * 1e-6, tracker_ppm=args.tracker_ppm,
                 force_relative=args.force_relative, force_absolute_N=args.force_absolute_n,
                 seed=args.seed)
    if args.noise:
        noise = api.read_noise(args.noise)
    if args.truth:
        data = api.simulate(robot, design, truth=args.truth, **noise)
    else:
        if not args.stiffness:
            raise UserError("give the truth: --truth truth.yaml or --stiffness k1,...,kn [N*m/rad]")
        try:
            k = [float(x) for x in args.stiffness.split(",")]
        except ValueError:
            raise UserError(f"--stiffness: '{args.stiffness}' is not a comma-separated list of numbers")
        data = api.simulate(robot, design, stiffness=k, **noise)
    data.write(args.output)
    print(f"wrote {len(data)} simulated measurements to {args.output}")
    return 0
