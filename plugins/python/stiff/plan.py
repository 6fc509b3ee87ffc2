"""Measurement planning: choose poses AND loads (docs/planning.md)."""
from __future__ import annotations

import ctypes as C
import json
import os
from typing import Callable, Optional, Sequence

import numpy as np

from . import _capi as _c
from . import _outputs
from ._capi import check, lib
from .api import Dataset, Robot, _Handle
from .errors import CancelledError, InvalidArgumentError

OPTIMIZERS = {"annealing": 1, "exchange": 2, "refine": 4}


def criteria() -> list[str]:
    """Names of the design criteria."""
    return [_c.get_string(lib.stiff_criterion_name, i) for i in range(lib.stiff_criterion_count())]


def evaluate_criteria(robot: Robot, design: Dataset, tracker_sigma_m: Optional[float] = None,
                      task: Optional[Dataset] = None) -> dict:
    """Every criterion's value for a given set of poses and loads; `task` (poses and loads of
    use) gives the `task` criterion a value (None without it). `tracker_sigma_m` weights the
    rows; None (or 0): the planning default, plan_defaults()["tracker_sigma_m"]."""
    return json.loads(_c.get_string(lib.stiff_criteria_task_json, robot, design, task,
                                    0.0 if tracker_sigma_m is None else tracker_sigma_m))


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


def plan_defaults() -> dict:
    """The library's planning defaults (stiff_plan_options_init): what every unset argument
    of plan() and every unset option of `stiff plan` takes."""
    o = _c.defaults(_c.PlanOptions)
    return {"count": o.count, "criterion": o.criterion.decode(), "seed": o.seed,
            "pool_poses": o.pool_poses, "pool_loads": o.pool_loads,
            "range_fraction": o.range_fraction, "load_range_N": (o.load_min_N, o.load_max_N),
            "load_step_N": o.load_step_N if o.load_step_N > 0 else 0.0,
            "min_sigma_m": o.min_sigma_m,
            "optimizers": tuple(k for k, v in OPTIMIZERS.items() if o.optimizers & v),
            "annealing_iterations": o.annealing_iterations,
            "annealing_t0": o.annealing_initial_temperature,
            "annealing_k0": o.annealing_initial_swap_count,
            "tracker_sigma_m": o.tracker_sigma_m, "tracker_ppm": o.tracker_ppm}


def plan(robot: Robot, count: Optional[int] = None, criterion: Optional[str] = None, *,
         seed: Optional[int] = None, pool_poses: Optional[int] = None,
         pool_loads: Optional[int] = None, range_fraction: Optional[float] = None,
         load_range_N: Optional[Sequence[float]] = None, load_step_N: Optional[float] = None,
         load_max_magnitude_N: Optional[float] = None, min_sigma_m: Optional[float] = None,
         q_fixed: Optional[Sequence[float]] = None, optimizers: Optional[Sequence[str]] = None,
         annealing_iterations: Optional[int] = None, annealing_t0: Optional[float] = None,
         annealing_k0: Optional[int] = None,
         candidate_file=None, task: Optional[Dataset] = None,
         tracker_sigma_m: Optional[float] = None, tracker_ppm: Optional[float] = None,
         workspace_box_m: Optional[Sequence[Sequence[float]]] = None,
         fixture_directions: Optional[Sequence[Sequence[float]]] = None,
         fixture_forces_N: Optional[Sequence[float]] = None,
         progress: Optional[Callable[[str, int, int, float], bool]] = None) -> Plan:
    """Plan `count` measurements (poses and loads) on `criterion` (default d_opt: it predicts
    best in the Monte-Carlo study of docs/paper-study.md; "kappa_a" is the paper's). An
    argument left at None takes the library's default (plan_defaults()); the library checks
    every value and its message names the option. `q_fixed` holds joints at values [rad]
    (NaN = free). `progress(optimizer, iteration, total, best_score)` may return False to
    stop (raises CancelledError); an exception it raises is re-raised here. `annealing_t0`
    is the annealing's initial temperature in cost units and `annealing_k0` the elements
    swapped per step at its start; 0 = automatic (T0 from random swaps of the start set,
    k0 = max(1, count / 3)). A load step <= 0 means continuous loads."""
    o = _c.defaults(_c.PlanOptions)

    # The C fields read 0 as "default": an explicit 0 or a negative count is refused with the
    # one message every count gets (require_count).
    if count is not None:
        o.count = _c.require_count("count", count)
    if criterion is not None:
        o.criterion = _c.encode(criterion)
    if seed is not None:
        o.seed = seed
    if pool_poses is not None:
        o.pool_poses = _c.require_count("pool_poses", pool_poses)
    if pool_loads is not None:
        o.pool_loads = _c.require_count("pool_loads", pool_loads)
    keep = _c.put_sampling(o, "plan", -1.0, range_fraction=range_fraction,
                           load_range_N=load_range_N, load_step_N=load_step_N,
                           min_sigma_m=min_sigma_m, q_fixed=q_fixed,
                           workspace_box_m=workspace_box_m)
    if load_max_magnitude_N is not None:
        o.load_max_magnitude_N = load_max_magnitude_N
    if annealing_iterations is not None:
        o.annealing_iterations = _c.require_count("annealing_iterations", annealing_iterations)
    if annealing_t0 is not None:
        o.annealing_initial_temperature = float(annealing_t0)
    if annealing_k0 is not None:
        if int(annealing_k0) != annealing_k0 or not 0 <= annealing_k0 <= 2**31 - 1:
            raise InvalidArgumentError(
                f"plan: the annealing's initial swap count k0 must be >= 0 (0: automatic) (got {annealing_k0})")
        o.annealing_initial_swap_count = int(annealing_k0)
    if tracker_sigma_m is not None:
        o.tracker_sigma_m = tracker_sigma_m
    if tracker_ppm is not None:
        o.tracker_ppm = tracker_ppm
    if optimizers is not None:
        mask = 0
        for name in optimizers:
            if name not in OPTIMIZERS:
                raise ValueError(f"unknown optimizer {name!r} (use {', '.join(OPTIMIZERS)})")
            mask |= OPTIMIZERS[name]
        o.optimizers = mask
    if candidate_file is not None:
        _outputs.note_input(candidate_file)
        o.candidate_file = _c.encode(os.fspath(candidate_file))
    if task is not None:
        o.task = task._h
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
