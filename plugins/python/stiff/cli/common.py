"""Helpers shared by the subcommands: built-in files, tables, atomic outputs."""
from __future__ import annotations

import argparse
import math
import os
import tempfile
from pathlib import Path

def data_dir() -> Path:
    """Built-in robots and example designs: bundled into the package, or the source tree."""
    from ..data import data_dir as _data_dir

    return _data_dir()


def robot_path(name_or_path: str) -> str:
    """A path, or the name of a built-in robot (rokae, puma560, ...)."""
    from ..data import find

    try:
        return find("robots", name_or_path)
    except FileNotFoundError as e:
        from . import UserError

        raise UserError(e.strerror) from None


def builtin_path(kind: str, name_or_path: str) -> str:
    """A path, or the name of a built-in truth, noise model or path (stiff.data)."""
    from ..data import find

    try:
        return find(kind, name_or_path)
    except FileNotFoundError as e:
        from . import UserError

        raise UserError(e.strerror) from None


def _vec3(text: str) -> list:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,z numbers, got {text!r}") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(f"expected 3 finite numbers x,y,z, got {text!r}")
    return v


def add_robot(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", "-r", required=True,
                   help="robot file (YAML or URDF) or built-in name (e.g. rokae)")
    g = p.add_argument_group("robot chain and tool (override the robot file; points in the "
                             "tip/flange frame, millimetres)")
    g.add_argument("--base", metavar="LINK",
                   help="URDF: first link of the chain (default: base_link, else the root)")
    g.add_argument("--tip", metavar="LINK",
                   help="URDF: last link of the chain (default: tool0 or flange when present, "
                   "else the only chain end; `stiff robot show` lists them)")
    g.add_argument("--measured-point", type=_vec3, metavar="X,Y,Z",
                   help="measured point (SMR) in the tip frame [mm]")
    g.add_argument("--load-point", type=_vec3, metavar="X,Y,Z",
                   help="point where the force acts, tip frame [mm] (default: the measured point)")
    g.add_argument("--tool-mass", type=float, metavar="KG", help="tool mass [kg]")
    g.add_argument("--tool-com", type=_vec3, metavar="X,Y,Z",
                   help="tool centre of mass in the tip frame [mm]")


def load_robot(args):
    """The robot of --robot with the chain and tool options of add_robot."""
    from .. import api

    mm = lambda v: None if v is None else [x * 1e-3 for x in v]
    return api.Robot(robot_path(args.robot), base=getattr(args, "base", None),
                     tip=getattr(args, "tip", None),
                     measured_point=mm(getattr(args, "measured_point", None)),
                     load_point=mm(getattr(args, "load_point", None)),
                     tool_mass=getattr(args, "tool_mass", None),
                     tool_com=mm(getattr(args, "tool_com", None)))


class Formatter(argparse.RawDescriptionHelpFormatter):
    pass


def table(headers, rows, aligns=None) -> str:
    """A plain aligned text table."""
    rows = [["" if c is None else str(c) for c in r] for r in rows]
    widths = [max(len(str(h)), *(len(r[i]) for r in rows)) if rows else len(str(h))
              for i, h in enumerate(headers)]
    aligns = aligns or ["<"] + [">"] * (len(headers) - 1)
    line = lambda cells: "  ".join(f"{c:{a}{w}}" for c, a, w in zip(cells, aligns, widths))
    out = [line([str(h) for h in headers]), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in rows]
    return "\n".join(out)


def fmt(v, spec=".4g", unit="") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:{spec}}{unit}"


def atomic_write_text(path, text: str) -> None:
    """Write a file atomically: temporary file in the same folder, renamed when complete."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


class ProgressBar:
    """A one-line progress bar on stderr (only when it is a terminal), and Ctrl-C as a clean
    stop: while active, SIGINT sets `interrupted` and the callback returns False."""

    def __init__(self, label: str = "", width: int = 30):
        import sys

        self.label, self.width, self.stream = label, width, sys.stderr
        self.tty = self.stream.isatty()
        self.interrupted = False
        self._last = ""

    def __enter__(self):
        import signal

        self._old = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def _on_sigint(self, *_):
        self.interrupted = True

    def __exit__(self, *exc):
        import signal

        signal.signal(signal.SIGINT, self._old)
        if self.tty and self._last:
            self.stream.write("\r" + " " * len(self._last) + "\r")
            self.stream.flush()
        return False

    def update(self, done: float, total: float, text: str = "") -> bool:
        if self.tty:
            frac = min(1.0, done / total) if total else 0.0
            n = int(frac * self.width)
            line = f"{self.label} [{'#' * n}{'.' * (self.width - n)}] {100 * frac:5.1f}% {text}"
            self.stream.write("\r" + line.ljust(len(self._last)))
            self.stream.flush()
            self._last = line
        return not self.interrupted
