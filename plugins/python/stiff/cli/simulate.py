"""stiff simulate: measurements from the virtual robot."""
from __future__ import annotations

from .. import api
from .common import (Formatter, add_robot, atomic_write_text, builtin_path, load_robot, robot_path,
                     whole)

EXAMPLE = """example:
  stiff simulate --robot rokae --plan plan.csv --stiffness 50914,16382,31311,7791,5614,4000 \\
      --tracker-sigma-um 10 -o data.csv
  stiff simulate --robot rokae --truth rokae_backlash --noise noise_realistic --count 60 -o data.csv

The truth file names the joint stiffness and any hidden effects (docs/formats.md); the noise
file the tracker sigma (constant + ppm), force and joint errors, outliers and the seed.
Both take a file or the name of a built-in one (`stiff examples` lists them). Without --plan,
--count random valid poses with loads of 15-35 N per axis are used. The output does not say
which effects the truth holds (a blind test stays blind) unless --record-truth."""


def register(sub):
    p = sub.add_parser("simulate", help="simulate loaded measurements on the virtual robot",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--plan", help="plan or measurement CSV giving poses and loads")
    p.add_argument("--count", type=whole, help="random poses when no --plan (default "
                   f"{api.random_design_defaults()['count']})")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--truth", help="truth YAML (stiffness and hidden effects)")
    g.add_argument("--stiffness", help="true joint stiffness, comma-separated [N*m/rad]")
    p.add_argument("--noise", help="noise YAML (overrides the noise options below)")
    # Unset options stay None: the library's default noise (stiff_noise_options_init) applies.
    d = api.noise_defaults()
    p.add_argument("--tracker-sigma-um", type=float,
                   help=f"tracker sigma per axis [um] (default {d['tracker_sigma_m'] * 1e6:g})")
    p.add_argument("--tracker-ppm", type=float,
                   help=f"distance-proportional tracker error [ppm] (default {d['tracker_ppm']:g})")
    p.add_argument("--force-relative", type=float,
                   help=f"relative force error, 1 sigma (default {d['force_relative']:g})")
    p.add_argument("--force-absolute-n", type=float,
                   help=f"absolute force error [N] (default {d['force_absolute_N']:g})")
    p.add_argument("--seed", type=int, default=None,
                   help=f"random seed of the design and the noise (default {d['seed']}; given, "
                   "it also replaces the noise file's seed)")
    p.add_argument("--record-truth", action="store_true",
                   help="write the truth's effects into the output's header (# truth_model:)")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.set_defaults(func=run)


def run(args):
    from . import UserError

    robot = load_robot(args)
    design = (api.Dataset.read(builtin_path("paper", args.plan), robot) if args.plan
              else api.random_design(robot, args.count, args.seed))
    # Only what the user gave; simulate() leaves every other noise field at the library's value.
    noise = dict(tracker_sigma_m=None if args.tracker_sigma_um is None else args.tracker_sigma_um * 1e-6,
                 tracker_ppm=args.tracker_ppm, force_relative=args.force_relative,
                 force_absolute_N=args.force_absolute_n, seed=args.seed)
    if args.noise:
        noise = api.read_noise(builtin_path("truths", args.noise))
        if args.seed is not None:
            noise["seed"] = args.seed
    truth = builtin_path("truths", args.truth) if args.truth else None
    if truth:
        data = api.simulate(robot, design, truth=truth, **noise)
    else:
        if not args.stiffness:
            raise UserError("give the truth: --truth truth.yaml or --stiffness k1,...,kn [N*m/rad]")
        try:
            k = [float(x) for x in args.stiffness.split(",")]
        except ValueError:
            raise UserError(f"--stiffness: '{args.stiffness}' is not a comma-separated list of numbers")
        data = api.simulate(robot, design, stiffness=k, **noise)
    data.write(args.output)
    if args.record_truth:
        _record_truth(args.output, truth, args.stiffness)
    print(f"wrote {len(data)} simulated measurements to {args.output}")
    return 0


def _record_truth(output, truth, stiffness) -> None:
    """Add the truth (its effects, or the stiffness) to the header comments of the output."""
    if truth:
        note = [f"# truth_model: {'+'.join(['joint'] + _truth_effects(truth))}",
                f"# truth_file: {truth}"]
    else:
        note = ["# truth_model: joint", f"# truth_stiffness_Nm_per_rad: {stiffness}"]
    from .._outputs import written

    with open(written(output), encoding="utf-8") as f:  # this command's output, not yet committed
        lines = f.read().splitlines()
    k = 0
    while k < len(lines) and lines[k].startswith("#"):
        k += 1
    atomic_write_text(output, "\n".join(lines[:k] + note + lines[k:]) + "\n")


def _truth_effects(truth) -> list:
    """Names of the block mapping under the truth file's top-level `effects:` key."""
    import re

    with open(truth, encoding="utf-8") as f:
        lines = f.read().splitlines()
    names, inside, indent = [], False, None
    for line in lines:
        body = line.split("#", 1)[0].rstrip()
        if not body:
            continue
        if not line[0].isspace():
            inside = body == "effects:"
            continue
        m = re.match(r"^(\s+)([A-Za-z_][A-Za-z0-9_]*)\s*:", body)
        if inside and m:
            indent = len(m.group(1)) if indent is None else indent
            if len(m.group(1)) == indent:
                names.append(m.group(2))
    return [n for n in names if n != "joint"]
