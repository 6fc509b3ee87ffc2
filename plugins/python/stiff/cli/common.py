"""Helpers shared by the subcommands: built-in files, tables, atomic outputs."""
from __future__ import annotations

import argparse
import math
import os
import tempfile
from pathlib import Path

_PKG = Path(__file__).resolve().parent.parent


def data_dir() -> Path:
    """Built-in robots and example designs: bundled into the package, or the source tree."""
    bundled = _PKG / "_data"
    if bundled.exists():
        return bundled
    src = _PKG.parent.parent.parent / "examples"
    return src


def robot_path(name_or_path: str) -> str:
    """A path, or the name of a built-in robot (rokae, puma560, ...)."""
    p = Path(name_or_path)
    if p.exists() or p.suffix in (".yaml", ".yml", ".urdf") or os.sep in name_or_path:
        return str(p)
    for ext in (".yaml", ".urdf"):
        cand = data_dir() / "robots" / (name_or_path + ext)
        if cand.exists():
            return str(cand)
    known = sorted(q.stem for q in (data_dir() / "robots").glob("*.*"))
    from . import UserError

    raise UserError(f"no robot file '{name_or_path}' and no built-in robot of that name "
                    f"(built-in: {', '.join(known)})")


def add_robot(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", "-r", required=True,
                   help="robot file (YAML or URDF) or built-in name (e.g. rokae)")


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
