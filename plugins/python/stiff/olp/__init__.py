"""Offline-programming plug-ins (docs/olp.md): vendor robot programs in, compensated programs
out (KUKA KRL, ABB RAPID, Fanuc LS), the FilterTarget-shaped per-target call, the Kienzle
milling-force model, the stiffness-aware tool orientation and a compensating wrapper for
RoboDK post-processors."""
from __future__ import annotations

import os
from typing import Optional

from .cutting import MATERIALS, KienzleMaterial, MillingCut, mean_force
from .program import (FilterError, FilterOptions, FilterResult, Program, ToolLoad, WrenchSpec,
                      filter_program)
from .target import POINT_CONFIG_CHANGE, Configuration, FilteredTarget, JointMap, filter_target

__all__ = ["read_program", "filter_file", "filter_program", "filter_target", "FilteredTarget",
           "FilterError", "FilterOptions", "FilterResult", "Program", "ToolLoad", "WrenchSpec",
           "JointMap", "Configuration", "KienzleMaterial", "MillingCut", "MATERIALS",
           "mean_force", "POINT_CONFIG_CHANGE"]


def read_program(path, *, frames: Optional[dict] = None, tools: Optional[dict] = None,
                 loads: Optional[dict] = None) -> Program:
    """Parse a program by its extension: .src (KRL, with its .dat), .mod/.modx/.prg (RAPID),
    .ls (Fanuc), .jbi (Yaskawa). frames/tools: {n: 4 x 4} controller frames the program refers
    to by number (KRL BASE_DATA/TOOL_DATA, Fanuc UFRAME/UTOOL, JBI USER/TOOL); loads: {n:
    ToolLoad} (KRL LOAD_DATA)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == ".src":
        from .krl import read_krl
        return read_krl(path, base_data=frames, tool_data=tools, load_data=loads)
    if ext in (".mod", ".modx", ".prg"):
        from .rapid import read_rapid
        return read_rapid(path)
    if ext == ".ls":
        from .fanuc import read_ls
        return read_ls(path, uframes=frames, utools=tools)
    if ext == ".jbi":
        from .jbi import read_jbi
        return read_jbi(path, uframes=frames, utools=tools)
    raise FilterError(f"{path}: unknown program type '{ext}' (KUKA .src, ABB .mod, Fanuc .ls, "
                      "Yaskawa .jbi)")


def filter_file(model, path, wrench: WrenchSpec, options: Optional[FilterOptions] = None,
                **frames) -> FilterResult:
    """read_program + filter_program."""
    return filter_program(read_program(path, **frames), model, wrench, options)
