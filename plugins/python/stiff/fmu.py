"""Export an identified model as an FMU (FMI 2.0 or 3.0) for co-simulation (docs/fmu.md)."""
from __future__ import annotations

import ctypes as C
import os
from pathlib import Path
from typing import Optional

from . import _capi as _c
from . import _outputs
from ._capi import check, lib
from .api import Fit, Robot
from .errors import InvalidArgumentError


def _default_binaries() -> str | None:
    bundled = Path(__file__).resolve().parent / "_lib" / "fmu"
    return str(bundled) if bundled.exists() else None


def fmu_defaults() -> dict:
    """The library's FMU export defaults (stiff_fmu_options_init): what every argument of
    export_fmu() left at None and every unset option of `stiff fmu export` takes."""
    o = _c.defaults(_c.FmuOptions)
    return {"fmi_version": o.fmi_version, "model_identifier": _c.text(o.model_identifier),
            "array_inputs": bool(o.array_inputs)}


def export_fmu(robot: Robot, fit: Fit, path, fmi_version: Optional[int] = None,
               model_identifier: Optional[str] = None, binaries_dir=None,
               array_inputs: Optional[bool] = None) -> Path:
    """Write `path` (.fmu): the fit's parameters as tunable start values, the robot in
    resources/. Inputs q1..qn [rad], fx..mz [N, N*m] (with `array_inputs`, FMI 3 only: the
    arrays q[n] and wrench[6] instead); outputs dx..rz [m, rad], the loaded tool position and
    the compensated joint targets q_cmd1..n. Written atomically. An argument left at None takes
    the library's default (fmu_defaults()); the library checks every value."""
    o = _c.defaults(_c.FmuOptions)
    if fmi_version is not None:
        if int(fmi_version) != fmi_version or fmi_version < 0:  # a uint32 field would wrap
            raise InvalidArgumentError(f"fmu export: fmi_version must be 2 or 3, not {fmi_version}", -1)
        if fmi_version == 0:  # the C field reads 0 as "default"
            raise InvalidArgumentError("fmu export: fmi_version must be 2 or 3, not 0", -1)
        o.fmi_version = int(fmi_version)
    if array_inputs is not None:
        o.array_inputs = 1 if array_inputs else 0
    if model_identifier is not None:
        o.model_identifier = _c.encode(model_identifier)
    b = binaries_dir if binaries_dir is not None else _default_binaries()
    if b is not None:
        o.binaries_dir = _c.encode(os.fspath(b))
    check(lib.stiff_fmu_export(_c.encode(_outputs.target(path)), robot, fit, C.byref(o)))
    return Path(path)
