"""stiff predict: predicted deflection of every row of a measurement or plan file."""
from __future__ import annotations

import numpy as np

from .. import api
from .common import (Formatter, add_limits_flag, add_robot, atomic_write_text, check_joint_limits,
                     load_robot, robot_path)

EXAMPLE = """example:
  stiff predict --robot rokae --fit fit.json --data valid.csv -o predicted.csv

Writes the predicted displacement of every row in the measurement format with the same ids;
when the data holds measured displacements, prints the RMS prediction error. On absolute data
(px, py, pz columns) it prints the position error (mean, RMS, max) and writes id, absolute,
x_m, y_m, z_m: the predicted position in the instrument frame (the displacement on
displacement rows); with measured orientations (a, b, c columns) also the orientation error
in degrees (mean, RMS, max) and rx_rad, ry_rad, rz_rad: the predicted probe orientation as a
rotation vector in the instrument frame.

Measured displacements are a session of their own: when the model has parameters of the
measurement session (drift: the warm-up restarts with every session), they are estimated from
the file's own readings, cross-fitted (each half of the rows predicted with the values from
the other half), as `stiff diagnose` scores validation data; --calibration-session applies the
fit's values instead (docs/effects.md, drift)."""


def register(sub):
    p = sub.add_parser("predict", help="predict the deflection for poses and loads",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--fit", "-f", required=True, help="fit JSON from `stiff identify`")
    p.add_argument("--data", "-d", required=True, help="measurement or plan CSV")
    p.add_argument("-o", "--output", help="CSV of predicted displacements to write")
    p.add_argument("--calibration-session", action="store_true",
                   help="measured displacements: apply the calibration session's drift instead of "
                        "estimating the file's own (cross-fitted)")
    add_limits_flag(p)
    p.set_defaults(func=run)


def run(args):
    robot = load_robot(args)
    fit = api.Fit.read(args.fit)
    data = api.Dataset.read(args.data, robot)
    check_joint_limits(robot, data, args.data, args.ignore_limits)
    model = api.Model(robot, fit)
    if data.position is not None:
        return run_absolute(args, robot, model, data, fit)
    pred = model.predict(data.q, data.wrench)
    measured = data.displacement
    if measured is not None and not args.calibration_session:
        own = model.predict_dataset(data, cross_fit_sessions=True)
        if not np.array_equal(own, model.predict_dataset(data)):
            pred[:, :3] = own
            print("the file's own session parameters (drift) are estimated from its readings, "
                  "cross-fitted (--calibration-session applies the fit's)")
    if measured is not None:
        err = measured - pred[:, :3]
        rms = float(np.sqrt(np.mean(err ** 2)))
        worst = int(np.argmax(np.linalg.norm(err, axis=1)))
        print(f"prediction error on {len(data)} measurements: RMS {rms * 1e6:.2f} um per axis, "
              f"max {np.linalg.norm(err[worst]) * 1e6:.2f} um at {data.ids[worst]}")
    if args.output:
        # A copy of the input keeps ids, metadata and extra columns; only d changes.
        out = api.Dataset.read(args.data, robot)
        out.displacement = pred[:, :3]
        out.write(args.output)
        print(f"wrote {args.output}")
    return 0



def run_absolute(args, robot, model, data, fit):
    """Absolute (or mixed) data: the predicted position in the instrument frame of each
    absolute row (displacement of the others), and the position error where measured."""
    pred = model.predict_dataset(data)
    err = np.linalg.norm(data.observed - pred, axis=1)
    ab = data.absolute
    if ab.any():
        e = err[ab]
        worst = int(np.flatnonzero(ab)[np.argmax(e)])
        print(f"absolute position error on {int(ab.sum())} rows: mean {e.mean() * 1e3:.4f} mm, "
              f"RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.4f} mm, max {e.max() * 1e3:.4f} mm "
              f"at {data.ids[worst]}")
    # The probe's orientation is a prediction only when the model has its frame on the flange.
    orients = any("orientation" in api.describe_effect(e)["needs"] for e in fit.model)
    measured_o = data.orientation if orients else None
    pred_o = model.predict_orientation(data) if measured_o is not None else None
    if measured_o is not None:
        has = ab & np.isfinite(measured_o).all(axis=1)
        if has.any():
            from ..compensate import rotation_vector_angle_between

            a = np.degrees(rotation_vector_angle_between(measured_o[has], pred_o[has]))
            worst = int(np.flatnonzero(has)[np.argmax(a)])
            print(f"absolute orientation error on {int(has.sum())} rows: mean {a.mean():.4f} deg, "
                  f"RMS {np.sqrt(np.mean(a ** 2)):.4f} deg, max {a.max():.4f} deg "
                  f"at {data.ids[worst]}")
    if (~ab).any() and data.displacement is not None:
        e = err[~ab]
        print(f"displacement error on {int((~ab).sum())} rows: RMS "
              f"{np.sqrt(np.mean(e ** 2) / 3) * 1e6:.2f} um per axis")
    if args.output:
        # The predicted value replaces the measured one; ids, sessions and metadata stay.
        import csv
        import io

        text = io.StringIO()
        w = csv.writer(text, lineterminator="\n")
        w.writerow(["id", "absolute", "x_m", "y_m", "z_m"] +
                   (["rx_rad", "ry_rad", "rz_rad"] if pred_o is not None else []))
        for i, r in enumerate(data.ids):
            w.writerow([r, int(ab[i])] + [repr(float(v)) for v in pred[i]] +
                       ([repr(float(v)) if ab[i] else "" for v in pred_o[i]]
                        if pred_o is not None else []))
        atomic_write_text(args.output, text.getvalue())
        print(f"wrote {args.output}")
    return 0
