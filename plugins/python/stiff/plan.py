"""Measurement planning: choose poses AND loads (docs/planning.md)."""
from __future__ import annotations

import ctypes as C
import json
import math
import os
from typing import Callable, Optional, Sequence

import numpy as np

from . import _capi as _c
from ._capi import check, lib
from .api import Dataset, Robot, _Handle
from .errors import CancelledError, InvalidArgumentError

OPTIMIZERS = {"annealing": 1, "exchange": 2, "refine": 4}


def criteria() -> list[str]:
    """Names of the design criteria."""
    return [_c.get_string(lib.stiff_criterion_name, i) for i in range(lib.stiff_criterion_count())]


def evaluate_criteria(robot: Robot, design: Dataset, tracker_sigma_m: float = 10e-6) -> dict:
    """Every criterion's value for a given set of poses and loads."""
    return json.loads(_c.get_string(lib.stiff_criteria_json, robot, design, tracker_sigma_m))


class Plan(_Handle):
    """A planned set of measurements: `.dataset` is the plan file, `.summary` the JSON."""

    _destroy = lib.stiff_plan_destroy

    def __init__(self, handle):
        self._own(handle)
        self.summary = json.loads(_c.get_string(lib.stiff_plan_json, self))

    @property
    def dataset(self) -> Dataset:
        h = C.c_void_p()
        check(lib.stiff_plan_dataset(C.byref(h), self))
        return Dataset(h)

    def write(self, path) -> None:
        """Write the plan file (CSV) atomically."""
        self.dataset.write(path)

    @property
    def criterion(self) -> str:
        return self.summary["criterion"]

    @property
    def value(self) -> float:
        return self.summary["value"]

    @property
    def criteria(self) -> dict:
        return self.summary["criteria"]

    def to_dataframe(self):
        import pandas as pd

        return pd.DataFrame(self.summary["measurements"])

    def __repr__(self) -> str:
        return (f"Plan({len(self.summary['measurements'])} measurements, {self.criterion} = "
                f"{self.value:.4g}, found by {self.summary['found_by']})")


def plan(robot: Robot, count: int = 10, criterion: str = "d_opt", *, seed: int = 1,
         pool_poses: int = 500, pool_loads: int = 100, range_fraction: float = 0.95,
         load_range_N: Sequence[float] = (15.0, 35.0), load_step_N: float = 5.0,
         load_max_magnitude_N: float = 0.0, min_sigma_m: float = 0.05,
         q_fixed: Optional[Sequence[float]] = None, optimizers: Sequence[str] = ("annealing", "exchange"),
         annealing_iterations: int = 100000, annealing_t0: float = 0.0, annealing_k0: int = 0,
         candidate_file=None, task: Optional[Dataset] = None,
         tracker_sigma_m: float = 10e-6, tracker_ppm: float = 0.0,
         workspace_box_m: Optional[Sequence[Sequence[float]]] = None,
         fixture_directions: Optional[Sequence[Sequence[float]]] = None,
         fixture_forces_N: Optional[Sequence[float]] = None,
         progress: Optional[Callable[[str, int, int, float], bool]] = None) -> Plan:
    """Plan `count` measurements (poses and loads) on `criterion` (default d_opt: it predicts
    best in the Monte-Carlo study of docs/paper-study.md; "kappa_a" is the paper's). `q_fixed` holds joints at
    values [rad] (NaN = free). `progress(optimizer, iteration, total, best_score)` may return
    False to stop (raises CancelledError); an exception it raises is re-raised here.
    `annealing_t0` is the annealing's initial temperature in cost units and `annealing_k0` the
    elements swapped per step at its start; 0 = automatic (T0 from random swaps of the start
    set, k0 = max(1, count / 3))."""
    # The C options read 0 as "library default": an explicit 0 must not silently become 10.
    if int(count) < 1:
        raise InvalidArgumentError(f"plan: count must be >= 1 (got {count})")
    if not 0 < range_fraction <= 1:
        raise InvalidArgumentError(f"plan: range_fraction must be in (0, 1] (got {range_fraction})")
    if not (math.isfinite(annealing_t0) and annealing_t0 >= 0):
        raise InvalidArgumentError(f"plan: annealing_t0 must be finite and >= 0 (got {annealing_t0})")
    if int(annealing_k0) != annealing_k0 or not 0 <= annealing_k0 <= 2**31 - 1:
        raise InvalidArgumentError(f"plan: annealing_k0 must be an integer >= 0 (got {annealing_k0})")
    o = _c.PlanOptions()
    o.struct_size = C.sizeof(o)
    o.count, o.criterion, o.seed = count, criterion.encode(), seed
    o.pool_poses, o.pool_loads, o.range_fraction = pool_poses, pool_loads, range_fraction
    o.load_min_N, o.load_max_N = float(load_range_N[0]), float(load_range_N[1])
    o.load_step_N = load_step_N if load_step_N > 0 else -1.0
    o.load_max_magnitude_N, o.min_sigma_m = load_max_magnitude_N, min_sigma_m
    keep = []
    if q_fixed is not None:
        qf = _c.as_array(q_fixed)
        keep.append(qf)
        o.q_fixed, o.q_fixed_count = _c.ptr(qf), qf.size
    mask = 0
    for name in optimizers:
        if name not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {name!r} (use {', '.join(OPTIMIZERS)})")
        mask |= OPTIMIZERS[name]
    o.optimizers, o.annealing_iterations = mask, annealing_iterations
    o.annealing_initial_temperature = float(annealing_t0)
    o.annealing_initial_swap_count = int(annealing_k0)
    if candidate_file is not None:
        o.candidate_file = _c.encode(os.fspath(candidate_file))
    if task is not None:
        o.task = task._h
    o.tracker_sigma_m, o.tracker_ppm = tracker_sigma_m, tracker_ppm
    if workspace_box_m is not None:
        lo, hi = (list(map(float, v)) for v in workspace_box_m)
        o.use_workspace_box = 1
        o.box_min_m[:], o.box_max_m[:] = lo, hi
    if fixture_directions is not None:
        if fixture_forces_N is None:
            raise ValueError("fixture_directions need fixture_forces_N")
        dirs = np.ascontiguousarray(fixture_directions, dtype=np.float64).reshape(-1, 3)
        forces = _c.as_array(fixture_forces_N).ravel()
        keep += [dirs, forces]
        o.fixture_directions, o.fixture_direction_count = _c.ptr(dirs), dirs.shape[0]
        o.fixture_forces_N, o.fixture_force_count = _c.ptr(forces), forces.size
    raised = []
    if progress is not None:
        def trampoline(opt, it, total, best, _):
            try:
                return 0 if progress(opt.decode(), it, total, best) is not False else 1
            except BaseException as e:  # re-raised after the C call returns
                raised.append(e)
                return 1
        cb = _c.PLAN_PROGRESS_FN(trampoline)
        o.progress = cb
    h = C.c_void_p()
    st = lib.stiff_plan_create(C.byref(h), robot, C.byref(o))
    if raised:
        raise raised[0]
    check(st)
    return Plan(h)
