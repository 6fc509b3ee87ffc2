"""stiff import: convert a laser tracker's export into the absolute measurement format."""
from __future__ import annotations

import sys

from .. import importer
from .common import Formatter

EXAMPLE = """examples:
  stiff import --preset jacobi2025 --session ur5 --id-prefix grid ur5_grid.csv -o grid.csv
  stiff import --preset landgraf2021 --session C measurements_random_poses.csv -o C.csv
  stiff import --sep ';' --decimal-comma --euler zyx --session cell1 --robot ur10 \\
      --map q1_deg=J1 --map q2_deg=J2 --map q3_deg=J3 --map q4_deg=J4 --map q5_deg=J5 \\
      --map q6_deg=J6 --map px_mm=X --map py_mm=Y --map pz_mm=Z \\
      --map a_deg=Rz --map b_deg=Ry --map c_deg=Rx export.csv -o cell1.csv

--map OUTPUT=EXPRESSION names where each quantity comes from: OUTPUT is a column of the
absolute format with its unit (id, session, q1_deg.., px_mm.., a_deg.., temp_C, fx_N..,
mx_Nm.., sigma_p_mm, sigma_o_deg); EXPRESSION is a source column, a sum of columns
(x_t + x_dif) or rms(c1, c2, c3). Options override the preset's. Table: docs/import.md."""


def register(sub):
    p = sub.add_parser("import", help="convert a tracker export into the measurement format",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    p.add_argument("input", help="the tracker program's export (a delimited text table)")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write")
    p.add_argument("--preset", choices=sorted(importer.PRESETS),
                   help="a known export format: " + "; ".join(
                       f"{k}: {v['description']}" for k, v in importer.PRESETS.items()))
    p.add_argument("--map", action="append", default=[], metavar="OUTPUT=EXPRESSION",
                   help="column mapping (repeat); overrides the preset's")
    p.add_argument("--sep", help="field separator (default ',' or the preset's)")
    p.add_argument("--decimal-comma", action="store_true", help="numbers use a decimal comma")
    p.add_argument("--euler", choices=importer.EULER,
                   help="Euler convention of a, b, c: xyz = Rx(a) Ry(b) Rz(c) (intrinsic), "
                        "zyx = Rz(a) Ry(b) Rx(c)")
    p.add_argument("--session", help="session label (one tracker placement) for every row")
    p.add_argument("--id-prefix", help="prefix of the ids (default: the session label)")
    p.add_argument("--robot", help="robot name written to the metadata")
    p.add_argument("--meta", action="append", default=[], metavar="KEY=VALUE",
                   help="extra metadata line (repeat)")
    p.add_argument("--every", type=int, default=1, metavar="K",
                   help="keep every K-th data row (subsampling; default all)")
    p.set_defaults(func=run)


def run(args):
    meta = {}
    for m in args.meta:
        if "=" not in m:
            raise importer.ImportFormatError(f"--meta '{m}' must be KEY=VALUE")
        k, v = m.split("=", 1)
        meta[k.strip()] = v.strip()
    res = importer.import_table(
        args.input, args.output, preset=args.preset, sep=args.sep,
        decimal="," if args.decimal_comma else None, columns=importer.parse_mapping(args.map),
        euler=args.euler, session=args.session, robot=args.robot, metadata=meta,
        every=args.every, id_prefix=args.id_prefix, command=None)
    note = f" (kept every {args.every}th, skipped {res.skipped})" if args.every > 1 else ""
    print(f"wrote {args.output}: {res.rows} rows{note}, columns {', '.join(res.columns)}")
    return 0
