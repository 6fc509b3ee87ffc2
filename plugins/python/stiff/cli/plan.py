"""stiff plan: choose the poses AND loads of a stiffness-identification experiment."""
from __future__ import annotations

import json
import math

import numpy as np

from .. import api
from ..errors import CancelledError
from ..plan import criteria as criterion_names
from ..plan import evaluate_criteria, plan, plan_defaults
from .common import (Formatter, ProgressBar, add_robot, atomic_write_text, builtin_path, fmt,
                     load_robot, robot_path, table, whole)

EXAMPLE = """example:
  stiff plan --robot rokae --count 10 --fix 6=0 -o plan.csv                        # d_opt
  stiff plan --robot rokae --count 10 --criterion kappa_a --fix 6=0 -o plan.csv     # the paper's
  stiff plan --robot rokae --criterion task --task machining.csv -o plan.csv
  stiff plan --robot rokae --count 30 --criterion d_opt --refine --json plan.json -o plan.csv
  stiff plan --robot rokae --evaluate design_kappa_a    # criteria of a given set (built-in)

Criteria (docs/planning.md): d_opt = log det A^T A (the default: in the Monte-Carlo study
docs/paper-study.md, under realistic tracker/force/joint errors, its sets predict the deflection
several times better than kappa_a's; use task when you know the poses and loads of use),
kappa_a = kappa_F^-1(A) of the stacked observation matrix (the paper's criterion; scale-free,
so it cannot see the load magnitude and tends to pick small deflections), kappa_j =
kappa_F^-1(J) of the stacked translational Jacobians (pose only), a_opt = tr (A^T A)^-1,
e_opt = smallest eigenvalue, o1 = observability index, task = expected RMS error of the predicted deflection
over --task poses and loads. The plan file is a measurement file without displacements, with
the load also in the flange frame (fx_flange_N ...: what the operator sets on the loading
fixture) and each measurement's contribution; `stiff simulate --plan` and tracker software
read it directly. Ctrl-C stops the search cleanly."""


def register(sub):
    p = sub.add_parser("plan", help="plan poses and loads of the experiment",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    d = plan_defaults()  # the library's defaults: one source for C, Python and this CLI
    p.add_argument("--count", "-n", type=whole, help=f"measurements N (default {d['count']})")
    p.add_argument("--criterion", "-c",
                   help=f"design criterion (default {d['criterion']}; the paper's is kappa_a; see "
                        "docs/paper-study.md)")
    p.add_argument("--seed", type=int, help=f"random seed (default {d['seed']})")
    p.add_argument("--pool-poses", type=whole, help=f"random candidate poses (default {d['pool_poses']})")
    p.add_argument("--pool-loads", type=whole, help=f"candidate loads (default {d['pool_loads']})")
    p.add_argument("--range", type=float,
                   help=f"fraction of each joint range (default {d['range_fraction']:g})")
    p.add_argument("--load-range", help="per-axis load magnitude range [N] (default "
                   f"{d['load_range_N'][0]:g},{d['load_range_N'][1]:g})")
    p.add_argument("--load-step", type=float,
                   help=f"load grid step [N], 0 = continuous (default {d['load_step_N']:g})")
    p.add_argument("--load-max", type=float, help="largest |F| [N] (default: unlimited)")
    p.add_argument("--min-sigma", type=float,
                   help="reject poses whose translational Jacobian has sigma_min below this [m] "
                        f"(default {d['min_sigma_m']:g})")
    p.add_argument("--fix", action="append", default=[], metavar="J=DEG",
                   help="hold joint J at DEG degrees (the paper holds 6=0); repeatable")
    p.add_argument("--iterations", type=whole,
                   help=f"annealing iterations (default {d['annealing_iterations']})")
    p.add_argument("--t0", type=float, metavar="T0",
                   help="annealing initial temperature in cost units (cost = 1/score for "
                        "kappa_a and kappa_j, -score otherwise; default 0 = automatic: from the "
                        "cost increases of random swaps of the start set)")
    p.add_argument("--k0", type=whole, metavar="K0",
                   help="elements the annealing swaps per step at the start, falling to 1 "
                        "(default 0 = automatic: max(1, N/3))")
    p.add_argument("--optimizers",
                   help=f"comma-separated: annealing, exchange (default {','.join(d['optimizers'])})")
    p.add_argument("--refine", action="store_true", help="refine poses and loads continuously with NLopt")
    p.add_argument("--candidates", help="CSV whose poses are the candidates")
    p.add_argument("--box", metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
                   help="workspace box of the measured point, base frame [mm]")
    p.add_argument("--fixture", metavar="X,Y,Z;X,Y,Z;...",
                   help="load directions of a loading fixture (base frame); with --fixture-forces")
    p.add_argument("--fixture-forces", metavar="F1,F2,...", help="force magnitudes along each fixture direction [N]")
    p.add_argument("--task", help="CSV of task poses and loads (for --criterion task)")
    p.add_argument("--tracker-sigma-um", type=float,
                   help=f"row weighting noise [um] (default {d['tracker_sigma_m'] * 1e6:g})")
    p.add_argument("--evaluate", help="only evaluate every criterion for this set (CSV)")
    p.add_argument("-o", "--output", help="plan file (CSV) to write")
    p.add_argument("--json", help="write the JSON summary here")
    p.set_defaults(func=run)


def _fixed(args, dof):
    from . import UserError

    q = np.full(dof, np.nan)
    for item in args.fix:
        try:
            j, v = item.split("=")
            j = int(j.lstrip("qQ"))
            if not 1 <= j <= dof:
                raise IndexError
            deg = float(v)
        except (ValueError, IndexError):
            raise UserError(f"--fix {item}: expected J=DEG with J in 1..{dof}, e.g. --fix 6=0")
        if not math.isfinite(deg):
            raise UserError(f"--fix {item}: the angle must be a finite number of degrees")
        q[j - 1] = math.radians(deg)
    return q if args.fix else None


def _print_criteria(values: dict) -> None:
    names = [n for n in criterion_names() if n in values]
    print(table(["criterion", "value"], [[n, fmt(values[n], ".5g")] for n in names]))


def run(args):
    from . import UserError

    robot = load_robot(args)
    if args.evaluate:
        design = api.Dataset.read(builtin_path("paper", args.evaluate), robot)
        values = evaluate_criteria(robot, design, None if args.tracker_sigma_um is None
                                   else args.tracker_sigma_um * 1e-6)
        print(f"{args.evaluate}: {int(values['count'])} measurements, {int(values['m'])} identifiable compliances")
        _print_criteria(values)
        if args.json:
            atomic_write_text(args.json, json.dumps(values, indent=2) + "\n")
        return 0
    if not args.output and not args.json:
        raise UserError("give -o plan.csv (and/or --json summary.json)")
    load_range = None
    if args.load_range is not None:
        try:
            load_range = tuple(float(x) for x in args.load_range.split(","))
            assert len(load_range) == 2
        except (ValueError, AssertionError):
            raise UserError(f"--load-range {args.load_range}: expected MIN,MAX in N")
    optimizers = None
    if args.optimizers is not None or args.refine:
        names = args.optimizers if args.optimizers is not None else ",".join(plan_defaults()["optimizers"])
        optimizers = [o.strip() for o in names.split(",") if o.strip()]
        if args.refine:
            optimizers.append("refine")
    task = api.Dataset.read(args.task, robot) if args.task else None
    box = None
    if args.box:
        try:
            v = [float(x) * 1e-3 for x in args.box.split(",")]
            assert len(v) == 6
        except (ValueError, AssertionError):
            raise UserError(f"--box {args.box}: expected six numbers XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX in mm")
        box = (v[:3], v[3:])
    dirs = forces = None
    if args.fixture or args.fixture_forces:
        try:
            dirs = [[float(x) for x in d.split(",")] for d in args.fixture.split(";")]
            forces = [float(x) for x in args.fixture_forces.split(",")]
            assert all(len(d) == 3 for d in dirs)
        except (ValueError, AssertionError, AttributeError):
            raise UserError("--fixture X,Y,Z;... and --fixture-forces F1,F2,... go together "
                            "(directions of three numbers, forces in N)")
    with ProgressBar("planning") as bar:
        def progress(optimizer, it, total, best):
            return bar.update(it, total or 1, f"{optimizer} best {best:.4g}")
        try:
            # Unset options stay None: the library fills its defaults and checks every value.
            result = plan(robot, args.count, args.criterion, seed=args.seed, pool_poses=args.pool_poses,
                          pool_loads=args.pool_loads, range_fraction=args.range, load_range_N=load_range,
                          load_step_N=args.load_step, load_max_magnitude_N=args.load_max,
                          min_sigma_m=args.min_sigma, q_fixed=_fixed(args, robot.dof),
                          optimizers=optimizers, annealing_iterations=args.iterations,
                          annealing_t0=args.t0, annealing_k0=args.k0,
                          candidate_file=args.candidates, task=task,
                          tracker_sigma_m=None if args.tracker_sigma_um is None else args.tracker_sigma_um * 1e-6,
                          workspace_box_m=box,
                          fixture_directions=dirs, fixture_forces_N=forces, progress=progress)
        except CancelledError:
            raise UserError("stopped (Ctrl-C); nothing written")
    s = result.summary
    rows = []
    for m in s["measurements"]:
        rows.append([m["id"], " ".join(f"{math.degrees(v):7.1f}" for v in m["q_rad"]),
                     " ".join(f"{v:6.1f}" for v in m["force_base_N"]),
                     " ".join(f"{v:6.1f}" for v in m["force_flange_N"]), fmt(m["contribution"], ".3f")])
    print(table(["id", "q [deg]", "F base [N]", "F flange [N]", "contribution"], rows,
                ["<", "<", "<", "<", ">"]))
    print()
    print(f"{s['criterion']} = {s['value']:.5g}, found by {s['found_by']}; pool {s['pool']['elements']} "
          f"elements ({s['pool']['poses']} poses x {s['pool']['loads']} loads), seed {s['seed']}")
    for t in s["trace"]:
        print(f"  {t['optimizer']:<10} best {t['best_value']:.5g} after {t['iterations']} iterations "
              f"({t['evaluations']} evaluations, {t['seconds'] * 1e3:.0f} ms)")
    print()
    _print_criteria(s["criteria"])
    if args.output:
        result.write(args.output)
        print(f"wrote {args.output}")
    if args.json:
        atomic_write_text(args.json, json.dumps(s, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0
