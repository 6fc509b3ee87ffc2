"""stiff identify: fit the model (compliance, geometry, other effects) to measured displacements
or absolute positions."""
from __future__ import annotations

import json
import sys
import math

from .. import api
from . import UserError
from .common import (Formatter, add_limits_flag, add_robot, check_joint_limits, fmt, load_robot,
                     plausibility_warnings, robot_path, table)

EXAMPLE = """example:
  stiff identify --robot rokae --data data.csv -o fit.json
  stiff identify --robot rokae --data data.csv --model joint+link+point_offset --loss huber -o fit.json
  stiff identify --robot ur5 --data examples/real/ur5/ur5_grid.csv --model registration+tool+joint_offset+kinematic -o ur5.json
  stiff identify --robot ur5 --data examples/real/ur5/ur5_random.csv --start ur5.json --refit registration -o ur5_moved.json

--model takes effect names joined by '+' (see `stiff effects`). The model 'joint' without a
robust loss is solved by linear least squares (Jiang & Fang 2023); anything else by Ceres.
Absolute measurements (px, py, pz in the instrument frame, docs/formats.md) need the geometric
effects: registration (one per session), tool, joint_offset, kinematic (docs/effects.md).
--start FIT --refit EFFECTS keeps every parameter of a previous fit except those of the listed
effects, which are fitted to this data: e.g. the registration of a new placement of the tracker
(a new session) to a robot calibrated before, from a few poses. The model is the start fit's
unless --model is given."""

MAX_OUTLIERS_SHOWN = 10  # outliers printed; the fit file lists them all


def register(sub):
    p = sub.add_parser("identify", help="identify joint stiffness (and effects) from measurements",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--data", "-d", required=True,
                   help="measurement CSV with displacements and/or absolute positions")
    # Unset options stay None: the library's defaults (stiff_identify_options_init) apply and
    # the library checks every value.
    d = api.identify_defaults()
    p.add_argument("--model", "-m", default=None,
                   help=f"effects joined by '+' (default: the --start fit's model, else {d['model']})")
    p.add_argument("--loss", help=f"none, huber, cauchy, soft_l1, tukey (default {d['loss']})")
    p.add_argument("--loss-scale-um", type=float,
                   help="robust loss scale [um] (default: from sigma_d or the data)")
    p.add_argument("--method", choices=list(api.METHODS),
                   help=f"default {d['method']}: linear least squares for the joint model "
                        "without robust loss on displacement data, else ceres")
    p.add_argument("--max-relative-se", type=float,
                   help="hold a parameter whose standard error exceeds this many times its "
                        "typical magnitude and also a third of its value, t < 3 "
                        "(docs/identifiability.md); "
                        f"0: structural rank test only (default {d['max_relative_se']:g})")
    p.add_argument("--orientation-length", type=float, metavar="M",
                   help="absolute rows with a measured orientation (and tool_orientation in the "
                        "model): an orientation error weighs as the position error it makes this "
                        "far from the probe (default: estimated from the residuals)")
    p.add_argument("--positions-only", action="store_true",
                   help="fit the positions alone, ignoring measured orientations")
    p.add_argument("--all-terms", action="store_true",
                   help="fit every optional term of the effects (nonlinear_joint's second-order "
                        "terms, gravity_compensator's second harmonics) instead of keeping only "
                        "those that lower the Bayesian information criterion "
                        "(docs/identifiability.md)")
    p.add_argument("--start", metavar="FIT",
                   help="a previous fit of this robot whose parameters start this one")
    p.add_argument("--refit", metavar="EFFECTS",
                   help="with --start: fit only these effects (joined by '+', e.g. "
                        "registration) and keep every other parameter of the start fit")
    p.add_argument("-o", "--output", help="fit JSON to write")
    p.add_argument("--json", action="store_true", help="print the fit as JSON instead of tables")
    add_limits_flag(p)
    p.set_defaults(func=run)


def _at_bound(fit: api.Fit) -> set:
    """Joints (1-based) the fit held at the bound c = 0 because least squares put their
    compliance below 0 (`held` is "bound"): determined, but not as a compliance."""
    return {int(p["name"][1:]) for p in fit.json["parameters"]
            if p["effect"] == "joint" and p.get("held") == "bound"}


def print_fit(fit: api.Fit, truth_stiffness=None) -> None:
    js = fit.json
    k, kse, ident = fit.stiffness, fit.stiffness_se, fit.identified
    bound = _at_bound(fit)
    rows = []
    for j in range(len(k)):
        held = "rigid (c < 0 held at 0)" if j + 1 in bound else "not identifiable"
        row = [f"{j + 1}", fmt(k[j], ".5g") if ident[j] else held,
               fmt(kse[j], ".2g") if ident[j] else "-",
               fmt(100 * kse[j] / k[j], ".2f", " %") if ident[j] and k[j] > 0 else "-"]
        if truth_stiffness is not None:
            t = truth_stiffness[j]
            row += [fmt(t, ".5g"), fmt(100 * (k[j] - t) / t, "+.2f", " %") if ident[j] else "-",
                    fmt(abs(k[j] - t) / kse[j], ".2f") if ident[j] and kse[j] > 0 else "-"]
        rows.append(row)
    head = ["joint", "k [N*m/rad]", "std. error", "rel. se"]
    if truth_stiffness is not None:
        head += ["true k", "error", "|error|/se"]
    print(table(head, rows))
    others = [p for p in js["parameters"] if p["effect"] != "joint"]
    if others:
        print()
        print(table(["effect", "parameter", "value", "std. error", "unit", "meaning"],
                    [[p["effect"], p["name"], fmt(p["value"], ".4g"), fmt(p["standard_error"], ".2g"),
                      p["unit"], p["meaning"][:60]] for p in others], ["<", "<", ">", ">", "<", "<"]))
    s = fit.statistics
    print()
    floor = f", noise floor {s.noise_floor_m * 1e6:.2f} um" if s.noise_floor_m > 0 else ""
    print(f"fit: {s.measurements} measurements, {s.rank} parameters identified, residual RMS "
          f"{s.rms_m * 1e6:.2f} um (sigma_hat {s.sigma_hat_m * 1e6:.2f} um{floor}), "
          f"condition number {s.condition_number:.3g}")
    if s.oriented_rows:
        print(f"     orientation of {s.oriented_rows} rows: residual RMS "
              f"{math.degrees(s.orientation_rms_rad):.4f} deg per axis, error mean "
              f"{math.degrees(s.orientation_mean_rad):.4f} deg, max "
              f"{math.degrees(s.orientation_max_rad):.4f} deg (weighed as "
              f"{s.orientation_length_m:.3g} m per rad)")
    if s.noise_floor_m > 0 and s.dof > 0:
        ratio = s.sigma_hat_m / s.noise_floor_m
        verdict = "at the noise floor" if ratio < 1.0 + 3.0 / math.sqrt(2 * s.dof) else \
            "ABOVE the noise floor: the model misses something (run `stiff diagnose`)"
        print(f"      residual / noise floor = {ratio:.2f}: {verdict}")
    if s.model_error_m > 0:
        o = (f" and {math.degrees(s.model_error_rad):.4f} deg" if s.model_error_rad > 0 else "")
        print(f"      the model's error, {s.model_error_m * 1e6:.2f} um{o} per axis, is added to each "
              "row's stated sigma in the weights")
    bad = [j + 1 for j in range(len(k)) if not ident[j] and j + 1 not in bound]
    if bound:
        print(f"held at the bound c = 0 (least squares put the compliance below 0): "
              f"joint{'s' if len(bound) > 1 else ''} {', '.join(map(str, sorted(bound)))}")
    if bad:
        print(f"not identifiable from this data: joint{'s' if len(bad) > 1 else ''} "
              f"{', '.join(map(str, bad))}")
    # The largest first; a long list buries the summary (the fit file keeps every one).
    shown = sorted(fit.outliers, key=lambda o: -o["residual_m"])[:MAX_OUTLIERS_SHOWN]
    for o in shown:
        print(f"outlier: measurement {o['id']} (row {o['row'] + 1}): residual "
              f"{o['residual_m'] * 1e6:.1f} um, weight {o['weight']:.2f} - {o['reason']}")
    if len(fit.outliers) > len(shown):
        print(f"outlier: ... and {len(fit.outliers) - len(shown)} more, smaller (all of them are "
              f"in the fit file's \"outliers\")")
    for w in fit.warnings:
        print(f"warning: {w}")


def run(args):
    robot = load_robot(args)
    data = api.Dataset.read(args.data, robot)
    check_joint_limits(robot, data, args.data, args.ignore_limits)
    if args.refit and not args.start:
        raise UserError("--refit needs --start FIT: the fit that gives the other parameters")
    start = api.Fit.read(args.start) if args.start else None
    model = args.model or ("+".join(start.model) if start is not None else None)
    try:
        fit = api.identify(robot, data, model=model, loss=args.loss,
                           loss_scale_m=None if args.loss_scale_um is None else args.loss_scale_um * 1e-6,
                           method=args.method,
                           max_relative_se=args.max_relative_se, start=start,
                           refit=args.refit, orientation_length_m=args.orientation_length,
                           use_orientation=not args.positions_only,
                           select_terms=False if args.all_terms else None)
    except Exception:
        # A fit that fails on implausible data: what is wrong with the data helps more.
        for w in plausibility_warnings(robot, data):
            print(f"warning: {w}", file=sys.stderr)
        raise
    if args.output:
        fit.write(args.output)
    if args.json:
        print(json.dumps(fit.json, indent=2))
    else:
        print_fit(fit)
        for w in plausibility_warnings(robot, data, fit):
            print(f"warning: {w}")
        if args.output:
            print(f"wrote {args.output}")
    return 0
