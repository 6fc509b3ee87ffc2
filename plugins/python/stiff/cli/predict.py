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
displacement rows)."""


def register(sub):
    p = sub.add_parser("predict", help="predict the deflection for poses and loads",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    add_robot(p)
    p.add_argument("--fit", "-f", required=True, help="fit JSON from `stiff identify`")
    p.add_argument("--data", "-d", required=True, help="measurement or plan CSV")
    p.add_argument("-o", "--output", help="CSV of predicted displacements to write")
    add_limits_flag(p)
    p.set_defaults(func=run)


def run(args):
    robot = load_robot(args)
    fit = api.Fit.read(args.fit)
    data = api.Dataset.read(args.data, robot)
    check_joint_limits(robot, data, args.data, args.ignore_limits)
    model = api.Model(robot, fit)
    if data.position is not None:
        return run_absolute(args, robot, model, data)
    pred = model.predict(data.q, data.wrench)
    measured = data.displacement
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



def run_absolute(args, robot, model, data):
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
        w.writerow(["id", "absolute", "x_m", "y_m", "z_m"])
        for i, r in enumerate(data.ids):
            w.writerow([r, int(ab[i])] + [repr(float(v)) for v in pred[i]])
        atomic_write_text(args.output, text.getvalue())
        print(f"wrote {args.output}")
    return 0
