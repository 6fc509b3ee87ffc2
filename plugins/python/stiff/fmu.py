"""Export an identified model as an FMU (FMI 2.0 or 3.0) for co-simulation (docs/fmu.md)."""
from __future__ import annotations

import ctypes as C
import os
from pathlib import Path

from . import _capi as _c
from . import _outputs
from ._capi import check, lib
from .api import Fit, Robot


def _default_binaries() -> str | None:
    bundled = Path(__file__).resolve().parent / "_lib" / "fmu"
    return str(bundled) if bundled.exists() else None


def export_fmu(robot: Robot, fit: Fit, path, fmi_version: int = 2,
               model_identifier: str = "stiff_arm", binaries_dir=None,
               array_inputs: bool = False) -> Path:
    """Write `path` (.fmu): the fit's parameters as tunable start values, the robot in
    resources/. Inputs q1..qn [rad], fx..mz [N, N*m] (with `array_inputs`, FMI 3 only: the
    arrays q[n] and wrench[6] instead); outputs dx..rz [m, rad], the loaded tool position and
    the compensated joint targets q_cmd1..n. Written atomically."""
    o = _c.FmuOptions()
    o.struct_size = C.sizeof(o)
    o.fmi_version = fmi_version
    o.array_inputs = 1 if array_inputs else 0
    o.model_identifier = _c.encode(model_identifier)
    b = binaries_dir if binaries_dir is not None else _default_binaries()
    o.binaries_dir = None if b is None else _c.encode(os.fspath(b))
    check(lib.stiff_fmu_export(_c.encode(_outputs.target(path)), robot, fit, C.byref(o)))
    return Path(path)
