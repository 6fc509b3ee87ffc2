"""Built-in files addressable by name: robots (`rokae`, `ur5`, ...), truths and noise models
(`rokae_backlash`, `noise_realistic`), example paths (`rokae_contour`, `pocket`) and the paper's
designs. They ship inside the package; `stiff.data.find("robots", "rokae")` gives the path."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_dir", "find", "names", "KINDS"]

_PKG = Path(__file__).resolve().parent

#: kind -> file suffixes tried, in order, after a bare name
KINDS = {
    "robots": (".yaml", ".urdf"),
    "truths": (".yaml",),
    "paths": (".csv", ".nc", ".gcode", ".ngc"),
    "paper": (".csv",),
}


def data_dir() -> Path:
    """Folder of the built-in files: bundled into the package, or the source tree's examples/."""
    bundled = _PKG / "_data"
    if bundled.exists():
        return bundled
    return _PKG.parent.parent.parent / "examples"


def names(kind: str) -> list[str]:
    """Names of the built-in files of one kind (without suffix)."""
    folder = data_dir() / kind
    return sorted({p.stem for p in folder.glob("*.*")}) if folder.is_dir() else []


def find(kind: str, name_or_path: "str | os.PathLike[str]") -> str:
    """A path that exists or names a folder is returned as given; a bare file name (with or
    without its suffix) is looked up among the built-in files of `kind` (robots, truths,
    paths, paper)."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind of built-in file {kind!r} (use {', '.join(KINDS)})")
    s = os.fspath(name_or_path)
    p = Path(s)
    if p.exists() or os.sep in s or "/" in s:
        return s
    for cand in [data_dir() / kind / s] + [data_dir() / kind / (s + ext) for ext in KINDS[kind]]:
        if cand.is_file():
            return str(cand)
    if p.suffix:
        return s  # a file name: the reader says it cannot open it
    known = ", ".join(names(kind)) or "none"
    what = {"robots": "robot", "truths": "truth or noise", "paths": "path", "paper": "design"}[kind]
    raise FileNotFoundError(2, f"no {what} file '{s}' and no built-in {what} of that name "
                               f"(built-in: {known})", s)
