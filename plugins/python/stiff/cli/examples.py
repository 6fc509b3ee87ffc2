"""stiff examples: the built-in robots, truths, noise models, paths and designs that every
command takes by name, where they are, and a copy to edit."""
from __future__ import annotations

import shutil
from pathlib import Path

from ..data import KINDS, data_dir, names
from .common import Formatter, table

EXAMPLE = """example:
  stiff examples                      # names and files
  stiff examples --copy my_examples   # copy them into a folder to edit

Every command takes these by name: --robot rokae, --truth rokae_backlash,
--noise noise_realistic, --path rokae_contour (or pocket.nc), --plan design_kappa_a.
Python: stiff.Robot("rokae"), stiff.data.find("paths", "pocket.nc")."""


def register(sub):
    p = sub.add_parser("examples", help="list (and copy) the built-in example files",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    p.add_argument("--copy", metavar="DIR", help="copy every built-in file into DIR (made if "
                   "missing; existing files are not overwritten)")
    p.set_defaults(func=run)


def run(args):
    base = data_dir()
    rows = []
    for kind in KINDS:
        for n in names(kind):
            files = sorted((base / kind).glob(n + ".*"))
            for f in files:
                rows.append([kind, n if len(files) == 1 else f.name, str(f)])
    print(table(["kind", "name", "file"], rows, ["<", "<", "<"]))
    if args.copy:
        dest = Path(args.copy)
        copied = skipped = 0
        for kind in KINDS:
            for f in sorted((base / kind).glob("*.*")):
                target = dest / kind / f.name
                target.parent.mkdir(parents=True, exist_ok=True)
                if target.exists():
                    skipped += 1
                    continue
                shutil.copyfile(f, target)
                copied += 1
        print(f"copied {copied} files into {dest}" +
              (f" ({skipped} already there, kept)" if skipped else ""))
    return 0
