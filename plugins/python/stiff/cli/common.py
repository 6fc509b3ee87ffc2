"""Helpers shared by the subcommands: built-in files, tables, atomic outputs."""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import numpy as np

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


def whole(text: str) -> int:
    """A count on the command line: 100000, or 1e5 as the help texts write it. Its range is
    checked by the library (one message for every count)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number")
    if not math.isfinite(v) or v != int(v):
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number")
    return int(v)


def add_limits_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--ignore-limits", action="store_true",
                   help="accept joint angles outside the robot file's limits (when the file's "
                   "limits are wrong; angles outside them usually mean degrees declared _rad)")


def check_joint_limits(robot, data, path, ignore: bool = False) -> None:
    """Measured joint angles must lie within the robot's limits: a file in degrees declared
    `_rad` gives angles of 170 rad that no arm reaches."""
    if ignore or len(data) == 0:
        return
    from . import UserError

    lo, hi = robot.limits
    q = data.q
    tol = 1e-9
    bad = np.argwhere((q < lo - tol) | (q > hi + tol))
    if bad.size:
        r, j = (int(x) for x in bad[0])
        raise UserError(
            f"{path}: measurement {data.ids[r]} (row {r + 1}): q{j + 1} = "
            f"{np.degrees(q[r, j]):.6g} deg is outside the limits [{np.degrees(lo[j]):.6g}, "
            f"{np.degrees(hi[j]):.6g}] deg of robot '{robot.name}' ({len(bad)} value(s) outside; "
            "check the angle unit of the columns, or --ignore-limits if the robot file's limits "
            "are wrong)")


def plausibility_warnings(robot, data, fit=None) -> list:
    """Warnings for results no robot gives: a joint stiffness far outside the range of
    industrial arms (1e2..1e8 N*m/rad, a decade beyond the softest and stiffest joints; with a
    fit), or a displacement larger than the reach (a unit mistake in the displacement columns)."""
    out = []
    for j, (k, ok) in enumerate(zip(fit.stiffness, fit.identified) if fit is not None else []):
        if ok and np.isfinite(k) and not 1e2 <= k <= 1e8:
            out.append(f"joint {j + 1}: stiffness {k:.3g} N*m/rad is outside 1e2..1e8 N*m/rad, "
                       "the range of industrial robots: check the displacement and force units "
                       "(mm declared _m?)")
    d = data.displacement
    if d is not None and len(data):
        for k, axis in enumerate("xyz"):
            if not np.any(d[:, k]):
                out.append(f"the displacement d{axis} is zero in every measurement: a tracker axis "
                           "that was not recorded? The fit and its noise-floor verdict treat it "
                           "as measured")
        reach = max(float(np.linalg.norm(robot.tool_pose(q)[:3, 3])) for q in data.q)
        worst = float(np.max(np.linalg.norm(d, axis=1)))
        if reach > 0 and worst > reach:
            out.append(f"a displacement of {worst:.3g} m is larger than the reach of the arm "
                       f"({reach:.3g} m): check the displacement units")
    return out


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
    """Write a text output like every other (stiff._outputs: atomic, committed with the
    command)."""
    from .._outputs import write_text

    write_text(path, text)


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
