"""stiff diagnose: compare the model with the measurements, see where it fails, learn which
physical effect it is missing, add it and watch the error fall."""
from __future__ import annotations

import json
import math
import shlex

from .. import api
from ..diagnose import diagnose, diagnose_defaults
from .common import (Formatter, add_robot, atomic_write_text, fmt, load_robot, robot_path, table,
                     whole)

EXAMPLE = """worked example (a hidden force-sensor clocking error on the virtual robot):
  stiff simulate --robot rokae --count 60 --seed 1 --truth rokae_force_clocking -o calib.csv
  stiff simulate --robot rokae --count 40 --seed 2 --truth rokae_force_clocking -o valid.csv
  stiff diagnose --robot rokae --data calib.csv --validate valid.csv --model joint \\
                 --report report.html --json diagnosis.json
      -> verdict missing_effect: force_frame (partial F = 52, p_adj = 1e-30,
         expected RMS drop 24 um); next: --model joint+force_frame
  stiff diagnose --robot rokae --data calib.csv --validate valid.csv --model joint+force_frame
      -> verdict adequate: fit and validation RMS at the noise floor
  stiff diagnose --robot rokae --data calib.csv --validate valid.csv --auto   # walk the loop

Verdicts: missing_effect (the top candidate, with the command that adds it), adequate
(residuals at the noise floor, nothing claimed), ambiguous (candidates this data cannot tell
apart, or one that the validation poses neither confirm nor refute, with an experiment that
would decide), unexplained (misfit that no candidate explains).
Statistics: group score / partial-F tests on the candidate regressors projected off the
current model, Holm-corrected (docs/diagnosis.md). The noise floor comes from sigma_d,
`# tracker_sigma_m` (plus the stated force-sensor error) or replicated measurements."""


def register(sub):
    p = sub.add_parser("diagnose", help="find the physical effect the model is missing",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--data", "-d", required=True, help="calibration CSV with displacements")
    p.add_argument("--validate", "-v", help="validation CSV (new poses) with displacements")
    # Unset options stay None: the library's defaults (stiff_diagnose_options_init) apply and the
    # library checks every value.
    d = diagnose_defaults()
    p.add_argument("--model", "-m", help=f"current model, effects joined by '+' (default {d['model']})")
    p.add_argument("--candidates", help="effects to test, joined by '+' (default: all not in the model)")
    p.add_argument("--alpha", type=float, help=f"family-wise error rate (Holm, default {d['alpha']:g})")
    p.add_argument("--auto", action="store_true", help="add the top effect while the evidence holds, re-fit, repeat")
    p.add_argument("--max-steps", type=whole, help="steps of --auto (default: the library's)")
    p.add_argument("--repeatability", type=float, metavar="MM",
                   help="the robot's pose repeatability from its data sheet (ISO 9283 RP) [mm]: on "
                        "absolute data a model whose held-out mean error is within it is adequate")
    p.add_argument("--report", help="HTML report to write (self-contained, with plots)")
    p.add_argument("--json", help="diagnosis JSON to write (docs/diagnosis.md)")
    p.set_defaults(func=run)


def _command_prefix(args) -> str:
    parts = ["stiff", "diagnose", "--robot", args.robot, "--data", args.data]
    if args.validate:
        parts += ["--validate", args.validate]
    if args.report:
        parts += ["--report", args.report]
    if args.json:
        parts += ["--json", args.json]
    return " ".join(shlex.quote(str(x)) for x in parts)


def um(v) -> str:
    return fmt(None if v is None else v * 1e6, ".2f", " um")


def print_text(d) -> None:
    fit = d["fit"]
    floor = d["noise_floor_m"]
    print(f"model {d['model']} on {fit['measurements']} measurements "
          f"({fit['measurements'] - fit['used']} outliers excluded), noise floor {um(floor)} "
          f"({d['noise_source']}"
          + (", with the force error along the arm's compliance" if d.get("noise_force_error")
             else "") + ")")
    line = f"  fit RMS {um(fit['rms_m'])}"
    if floor > 0:
        line += (f", chi2 {fit['chi2']:.1f} for {fit['dof']} dof (p = {fit['chi2_p']:.2g}): "
                 + ("ABOVE the noise floor" if fit["omnibus_rejects"] else "at the noise floor"))
    print(line)
    if "validation" in d:
        v = d["validation"]
        print(f"  validation RMS {um(v['rms_m'])} (floor {um(v['floor_m'])})")
    w = d["where"]
    worst = w["worst_poses"][:3]
    if worst:
        print("  worst poses: " + ", ".join(
            f"{p['id']} {um(p['norm_m'])}" + (f" ({p['norm_sigma']:.1f} sigma)" if p["norm_sigma"] else "")
            + (" outlier" if p["outlier"] else "") for p in worst))
    sig = [c for c in w["covariates"] if c["significant"]][:4]
    if sig:
        print("  residual structure: " + ", ".join(
            f"{c['covariate']} (F {c['statistic']:.3g}, p_adj {c['p_adjusted']:.2g}, "
            f"{100 * c.get('share', 0):.0f} % of the residual)" for c in sig))
    print()
    rows = []
    for c in d["candidates"]:
        if c["testable"]:
            rows.append([c["rank"], c["effect"], f"{c['statistic']:.3g}", c["df"],
                         f"{c['p_adjusted']:.2g}", um(c["expected_rms_drop_m"]),
                         "yes" if c["identifiable"] else "partly",
                         "*" if c["significant"] else "", "+".join(c["group"]) if len(c["group"]) > 1 else ""])
        else:
            rows.append(["-", c["effect"], "-", "-", "-", "-", "no", "", c["reason"][:60]])
    print(table(["rank", "candidate", "F", "df", "p_adj", "RMS drop", "identifiable", "sig", "group / note"],
                rows, [">", "<", ">", ">", ">", ">", "<", "<", "<"]))
    print()
    print(f"verdict: {d['verdict']}")
    print("  " + d["summary"])
    if d["suggested_command"] and d["verdict"] in ("missing_effect", "ambiguous"):
        print(f"  next: {d['suggested_command']}")
    if len(d["steps"]) > 1:
        print()
        def cv_rms(s):  # the calibration poses cross-validated (absolute data), per axis
            e = [x for x in s.get("cross_validation_error_m") or [] if x is not None]
            return math.sqrt(sum(x * x for x in e) / (3 * len(e))) if e else None

        print(table(["step", "added", "model", "fit RMS", "validation RMS", "cross-validated RMS",
                     "verdict"],
                    [[s["step"], s["added"] or "-", s["model"], um(s["rms_m"]),
                      um(s.get("validation_rms_m")), um(cv_rms(s)), s["verdict"]]
                     for s in d["steps"]],
                    [">", "<", "<", ">", ">", ">", "<"]))
        print(f"final model: {d['final_model']} ({d['final_verdict']})")
    for note in d.get("notes", []):
        print(f"note: {note}")
    for wmsg in d["warnings"]:
        print(f"warning: {wmsg}")


def run(args):
    robot = load_robot(args)
    calib = api.Dataset.read(args.data, robot)
    valid = api.Dataset.read(args.validate, robot) if args.validate else None
    d = diagnose(robot, calib, valid, model=args.model, candidates=args.candidates,
                 alpha=args.alpha, auto_loop=args.auto or None,
                 auto_steps=args.max_steps if args.auto else None,
                 command_prefix=_command_prefix(args),
                 repeatability_m=args.repeatability * 1e-3 if args.repeatability is not None else None)
    print_text(d)
    if args.json:
        atomic_write_text(args.json, json.dumps(d.json, indent=1))
        print(f"wrote {args.json}")
    if args.report:
        from ..report import diagnosis_report

        atomic_write_text(args.report, diagnosis_report(d, title=f"stiff diagnose: {args.data}"))
        print(f"wrote {args.report}")
    return 0
