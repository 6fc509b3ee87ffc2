"""Planning through the Python API and the command line."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import stiff


def test_plan_beats_the_printed_design_on_its_own_criterion(rokae_path, design_a):
    robot = stiff.Robot(rokae_path)
    printed = stiff.evaluate_criteria(robot, stiff.Dataset.read(design_a, robot))
    p = stiff.plan(robot, 10, "kappa_a", q_fixed=[np.nan] * 5 + [0.0], annealing_iterations=20000)
    assert p.value >= printed["kappa_a"]
    ds = p.dataset
    assert len(ds) == 10 and ds.displacement is None
    np.testing.assert_array_equal(ds.q[:, 5], 0.0)
    f = np.abs(ds.force)
    assert f.min() >= 15 - 1e-9 and f.max() <= 35 + 1e-9
    # The flange-frame load has the same magnitude as the base-frame load.
    m = p.summary["measurements"][0]
    assert np.isclose(np.linalg.norm(m["force_base_N"]), np.linalg.norm(m["force_flange_N"]))


def test_progress_callback_can_stop_and_exceptions_propagate(rokae_path):
    robot = stiff.Robot(rokae_path)
    calls = []
    with pytest.raises(stiff.CancelledError):
        stiff.plan(robot, 10, progress=lambda *a: calls.append(a) or len(calls) < 3)
    assert len(calls) == 3

    def boom(*a):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        stiff.plan(robot, 10, progress=boom)


@pytest.mark.parametrize("kwargs, message", [
    (dict(count=100000), "pool"),
    (dict(count=1), "3N"),
    (dict(criterion="nope"), "unknown plan criterion"),
    (dict(load_range_N=(40, 20)), "load"),
    (dict(annealing_t0=-1.0), "initial temperature T0"),
    (dict(annealing_t0=float("nan")), "initial temperature T0"),
    (dict(annealing_t0=float("inf")), "initial temperature T0"),
    (dict(annealing_k0=-1), "initial swap count k0"),
    (dict(pool_poses=0), "pool_poses must be an integer >= 1"),
    (dict(annealing_iterations=-1), "annealing_iterations must be an integer >= 1"),
])
def test_bad_requests_are_clear_errors(rokae_path, kwargs, message):
    robot = stiff.Robot(rokae_path)
    args = dict(count=10, pool_poses=50, pool_loads=10, annealing_iterations=1000)
    args.update(kwargs)
    with pytest.raises(stiff.InvalidArgumentError, match=message):
        stiff.plan(robot, args.pop("count"), **args)


def test_cli_plan_writes_plan_file_and_json(tmp_path, rokae_path):
    out = subprocess.run([sys.executable, "-m", "stiff.cli", "plan", "--robot", rokae_path, "--count", "10",
                          "--criterion", "kappa_a", "--fix", "6=0", "--iterations", "5000",
                          "-o", tmp_path / "plan.csv", "--json", tmp_path / "plan.json"],
                         capture_output=True, text=True, check=True).stdout
    assert "kappa_a =" in out and "found by" in out
    header = [l for l in (tmp_path / "plan.csv").read_text().splitlines() if not l.startswith("#")][0]
    assert "fx_flange_N" in header and "contribution" in header and "q6_rad" in header
    summary = json.loads((tmp_path / "plan.json").read_text())
    assert set(stiff.criteria()) <= set(summary["criteria"])


def _annealing_trace(summary):
    return next(t for t in summary["trace"] if t["optimizer"] == "annealing")


def test_annealing_t0_and_k0_reach_the_optimizer(rokae_path):
    robot = stiff.Robot(rokae_path)
    args = dict(pool_poses=50, pool_loads=10, optimizers=["annealing"], annealing_iterations=500)
    t = _annealing_trace(stiff.plan(robot, 10, annealing_t0=0.125, annealing_k0=2, **args).summary)
    assert t["initial_temperature"] == 0.125 and t["initial_swap_count"] == 2
    # 0 = automatic: T0 from random swaps, k0 = max(1, N / 3).
    t = _annealing_trace(stiff.plan(robot, 10, **args).summary)
    assert t["initial_temperature"] > 0 and t["initial_swap_count"] == 3


def test_options_are_checked_once_with_one_message_on_every_surface(rokae_path, tmp_path):
    # The core checks the options (check_plan_options) before building the pool; the C ABI,
    # Python and the command line show its message unchanged.
    import ctypes as C

    from stiff import _capi

    robot = stiff.Robot(rokae_path)
    o = _capi.PlanOptions()
    _capi.check(_capi.lib.stiff_plan_options_init(C.byref(o), C.sizeof(o)))
    o.annealing_initial_temperature = -1.0
    h = C.c_void_p()
    with pytest.raises(stiff.InvalidArgumentError) as from_c:
        _capi.check(_capi.lib.stiff_plan_create(C.byref(h), robot, C.byref(o)))
    assert not h.value
    with pytest.raises(stiff.InvalidArgumentError) as from_python:
        stiff.plan(robot, annealing_t0=-1.0)
    cli = subprocess.run([sys.executable, "-m", "stiff.cli", "plan", "--robot", rokae_path, "--t0", "-1",
                          "-o", tmp_path / "p.csv"], capture_output=True, text=True)
    message = "the annealing's initial temperature T0 must be finite and >= 0 (0: automatic) (got -1)"
    assert message in str(from_c.value) and message in str(from_python.value)
    assert cli.returncode == 2 and message in cli.stderr and "Traceback" not in cli.stderr


def test_defaults_come_from_the_library(rokae_path):
    # stiff_plan_options_init is the one place the defaults are written: the Python function
    # and the command line's help show the same values, and an unset argument takes them.
    d = stiff.plan_defaults()
    assert d["count"] == 10 and d["criterion"] == "d_opt" and d["pool_poses"] == 500
    assert d["annealing_iterations"] == 100000 and d["load_range_N"] == (15.0, 35.0)
    assert d["optimizers"] == ("annealing", "exchange") and d["tracker_sigma_m"] == 10e-6
    help_text = subprocess.run([sys.executable, "-m", "stiff.cli", "plan", "--help"],
                               capture_output=True, text=True, check=True).stdout
    for text in (f"default {d['count']})", f"default {d['pool_poses']})",
                 f"default {d['annealing_iterations']})", "default 15,35)"):
        assert text in " ".join(help_text.split()), text
    robot = stiff.Robot(rokae_path)
    p = stiff.plan(robot, pool_poses=40, pool_loads=10, annealing_iterations=500)
    assert len(p.summary["measurements"]) == d["count"] and p.criterion == d["criterion"]


def test_cli_plan_t0_and_k0(tmp_path, rokae_path):
    cmd = [sys.executable, "-m", "stiff.cli", "plan", "--robot", rokae_path, "--count", "10",
           "--pool-poses", "50", "--pool-loads", "10", "--optimizers", "annealing",
           "--iterations", "500"]
    subprocess.run(cmd + ["--t0", "0.125", "--k0", "2", "--json", tmp_path / "plan.json"],
                   capture_output=True, text=True, check=True)
    t = _annealing_trace(json.loads((tmp_path / "plan.json").read_text()))
    assert t["initial_temperature"] == 0.125 and t["initial_swap_count"] == 2
    bad = subprocess.run(cmd + ["--t0", "-1", "--json", tmp_path / "bad.json"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "T0" in bad.stderr and "got -1" in bad.stderr
    assert "Traceback" not in bad.stderr
    assert not (tmp_path / "bad.json").exists()


def _task_value_numpy(robot, design, task, sigma_m=10e-6):
    """An independent numpy implementation of the task criterion sqrt(tr(M^-1 S) / 3) [m]
    (docs/planning.md): M from the design's observation blocks A_i[r, k] = J[r, k] (J[:, k] . F)
    weighted by 1/sigma^2, S the mean of the task's B^T B, over joints 1-5 (joint 6 has no
    lever arm at the flange centre)."""
    def blocks(q, force):
        out = []
        for qi, fi in zip(np.atleast_2d(q), np.atleast_2d(force)):
            j = robot.jacobian(qi)[:3, :5]
            out.append(j * (j.T @ fi)[None, :])
        return np.array(out)
    a = blocks(design.q, design.force) / sigma_m
    m = np.einsum("nrk,nrl->kl", a, a)
    b = blocks(task.q, task.force)
    s = np.einsum("nrk,nrl->kl", b, b) / b.shape[0]
    return math.sqrt(np.trace(np.linalg.solve(m, s)) / 3)


def test_task_criterion_of_a_given_set_equals_an_independent_computation(rokae_path):
    robot = stiff.Robot(rokae_path)
    design = stiff.Dataset.read(os.path.join(os.path.dirname(rokae_path), "..", "paper",
                                             "design_kappa_a.csv"), robot)
    task = stiff.random_design(robot, 15, seed=4)
    values = stiff.evaluate_criteria(robot, design, task=task)
    assert values["task"] == pytest.approx(_task_value_numpy(robot, design, task), rel=1e-9)
    assert stiff.evaluate_criteria(robot, design)["task"] is None
