"""Model diagnosis: which physical effect is the compliance model missing?

``diagnose(robot, calibration, validation=None, model="joint")`` fits the model, compares it
with the noise floor, tests every candidate effect of the library (group score / partial-F
tests on the regressors the current model cannot absorb, Holm-corrected) and returns a
:class:`Diagnosis`: a read-only, dict-like view of the JSON result (docs/diagnosis.md)."""
from __future__ import annotations

import ctypes as C
import json
from collections.abc import Mapping
from typing import Iterable, Optional, Union

from . import _capi as _c
from ._capi import check, lib
from .api import Dataset, Robot
from .errors import InvalidArgumentError

__all__ = ["Diagnosis", "diagnose", "diagnose_defaults", "VERDICTS"]

VERDICTS = ("missing_effect", "adequate", "ambiguous", "unexplained")


class Diagnosis(Mapping):
    """Result of :func:`diagnose`: ``d["verdict"]``, ``d["candidates"]``, ... (the JSON of
    docs/diagnosis.md), plus shortcuts and ``to_dataframe()`` (the candidate ranking)."""

    def __init__(self, data: dict):
        self._d = data

    def __getitem__(self, key):
        return self._d[key]

    def __iter__(self):
        return iter(self._d)

    def __len__(self):
        return len(self._d)

    @property
    def json(self) -> dict:
        return self._d

    def dumps(self, indent: int = 1) -> str:
        return json.dumps(self._d, indent=indent)

    @property
    def verdict(self) -> str:
        return self._d["verdict"]

    @property
    def top(self) -> Optional[dict]:
        """The best testable candidate (None if there is none)."""
        tested = [c for c in self._d["candidates"] if c["testable"]]
        return tested[0] if tested else None

    @property
    def candidates(self) -> list:
        return self._d["candidates"]

    def to_dataframe(self):
        """The candidate ranking as a pandas DataFrame (pandas is optional)."""
        import pandas as pd

        cols = ["rank", "effect", "statistic", "df", "p_value", "p_adjusted", "significant",
                "expected_rms_drop_m", "identifiable", "testable", "group", "reason", "command"]
        return pd.DataFrame([{k: c.get(k) for k in cols} for c in self._d["candidates"]])

    def __repr__(self) -> str:
        d = self._d
        top = self.top
        parts = [f"verdict={d['verdict']!r}", f"model={d['model']!r}",
                 f"fit={d['fit']['rms_m'] * 1e6:.2f} um"]
        if "validation" in d:
            parts.append(f"validation={d['validation']['rms_m'] * 1e6:.2f} um")
        parts.append(f"floor={d['noise_floor_m'] * 1e6:.2f} um")
        if top is not None:
            parts.append(f"top={top['effect']!r} (p_adj={top['p_adjusted']:.2g}, "
                         f"drop={top['expected_rms_drop_m'] * 1e6:.1f} um)")
        return "Diagnosis(" + ", ".join(parts) + ")"


def _join(v: Union[None, str, Iterable[str]]) -> Optional[bytes]:
    if v is None:
        return None
    if not isinstance(v, str):
        v = "+".join(v)
    return v.encode("utf-8")


def diagnose_defaults() -> dict:
    """The library's diagnosis defaults (stiff_diagnose_options_init): what every argument of
    diagnose() left at None and every unset option of `stiff diagnose` takes (candidates None:
    every effect not in the model; auto_loop False: no loop; auto_steps 0: the library's
    number of steps when the loop is walked)."""
    o = _c.defaults(_c.DiagnoseOptions)
    return {"model": _c.text(o.model), "candidates": _c.text(o.candidates), "alpha": o.alpha,
            "auto_loop": bool(o.auto_loop), "auto_steps": o.auto_steps,
            "command_prefix": _c.text(o.command_prefix), "repeatability_m": o.repeatability_m}


def diagnose(robot: Robot, calibration: Dataset, validation: Optional[Dataset] = None,
             model: Union[None, str, Iterable[str]] = None, candidates=None,
             alpha: Optional[float] = None, auto_steps: Optional[int] = None,
             command_prefix: Optional[str] = None, auto_loop: Optional[bool] = None,
             repeatability_m: Optional[float] = None) -> Diagnosis:
    """Diagnose ``model`` (e.g. "joint" or "joint+link") on ``calibration``.

    candidates: effects to test ('+'-joined or a list; default every effect not in the model);
    alpha: family-wise error rate (Holm); auto_steps: > 0 walks the loop (add the top effect,
    re-fit, re-score) up to that many times; auto_loop: walk the loop, with the library's number
    of steps unless auto_steps gives one; command_prefix: start of the suggested commands;
    repeatability_m: the robot's pose repeatability [m] (ISO 9283 RP, from its data sheet): on
    absolute data a model whose held-out mean error is within it is adequate.
    An argument left at None takes the library's default (diagnose_defaults()); the library
    checks every value and its message names the option."""
    o = _c.defaults(_c.DiagnoseOptions)
    if model is not None:
        o.model = _join(model)
    if candidates is not None:
        o.candidates = _join(candidates)
    if alpha is not None:
        if alpha == 0:  # the C field reads 0 as "default"; the library checks every other value
            raise InvalidArgumentError(f"diagnose: alpha must be in (0, 1) (got {alpha})", -1)
        o.alpha = float(alpha)
    if auto_steps is not None:
        if int(auto_steps) != auto_steps or auto_steps < 0:  # a uint32 field would wrap around
            raise InvalidArgumentError(
                f"diagnose: auto_steps must be a whole number >= 0 (got {auto_steps})", -1)
        o.auto_steps = int(auto_steps)
    if auto_loop is not None:
        o.auto_loop = 1 if auto_loop else 0
    if command_prefix is not None:
        o.command_prefix = _c.encode(command_prefix)
    if repeatability_m is not None:
        o.repeatability_m = float(repeatability_m)
    h = C.c_void_p()
    check(lib.stiff_diagnose(C.byref(h), robot, calibration,
                             validation if validation is not None else None, C.byref(o)))
    try:
        text = _c.get_string(lib.stiff_diagnosis_json, h)
    finally:
        lib.stiff_diagnosis_destroy(h)
    return Diagnosis(json.loads(text))
