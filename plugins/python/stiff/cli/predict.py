"""stiff predict: predicted deflection of every row of a measurement or plan file."""
from __future__ import annotations

import numpy as np

from .. import api
from .common import Formatter, add_limits_flag, add_robot, check_joint_limits, load_robot, robot_path

EXAMPLE = """example:
  stiff predict --robot rokae --fit fit.json --data valid.csv -o predicted.csv

Writes the predicted displacement of every row in the measurement format with the same ids;
when the data holds measured displacements, prints the RMS prediction error."""


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
    pred = api.Model(robot, fit).predict(data.q, data.wrench)
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

