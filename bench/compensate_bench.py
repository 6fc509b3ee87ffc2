"""Compensation throughput through the Python API (docs/benchmarks.md, "Compensation").

Points per second of stiff.compensate_path on a 1e5-point circle path (one C call; the loop
over points runs in C), rokae arm, joint model with the paper's stiffness, constant wrench;
and, beside it, the C++ figure of bench/compensate_benchmark.cpp when its binary is given.

Usage: STIFF_LIBRARY=build-comp/capi/libstiff_c.so PYTHONPATH=plugins/python \\
       .venv/bin/python bench/compensate_bench.py [--points N] [--cxx build-comp/bench/stiff_compensate_benchmark]
"""
import argparse
import json
import pathlib
import subprocess
import tempfile
import time

import numpy as np

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # idle BLAS threads would count as CPU time

import stiff  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
K = [5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cxx", help="stiff_compensate_benchmark binary")
    a = ap.parse_args()
    robot = stiff.Robot(ROOT / "examples" / "robots" / "rokae.yaml")
    with tempfile.TemporaryDirectory() as d:
        data = stiff.simulate(robot, stiff.random_design(robot, 30, 1), stiffness=K,
                              tracker_sigma_m=0.0)
        fit = stiff.identify(robot, data)
        model = stiff.Model(robot, fit)
    n = a.points
    t = 2 * np.pi * np.arange(n) / n
    poses = np.tile(np.diag([1.0, -1.0, -1.0, 1.0]), (n, 1, 1))
    poses[:, 0, 3] = 0.45 + 0.08 * np.cos(t)
    poses[:, 1, 3] = 0.08 * np.sin(t)
    poses[:, 2, 3] = -0.15
    wrench = np.array([-60.0, 40.0, -120.0, 0, 0, 0])
    rows = {}
    for label, kw in [("compensate_path (q_cmd only)", dict(nominal=False, targets=False)),
                      ("compensate_path (+ nominal IK + FK targets)", dict())]:
        best, best_cpu = float("inf"), float("inf")
        for _ in range(a.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            res = stiff.compensate_path(model, poses, wrench, **kw)
            best = min(best, time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
        assert not res.problems()
        rows[label] = n / best_cpu
        print(f"{label:45s} {n / best_cpu:10.3e} points/s CPU, {n / best:10.3e} wall "
              f"({best_cpu * 1e3:.0f} ms CPU for {n} points)")
    if a.cxx:
        out = subprocess.run([a.cxx, "--benchmark_format=json",
                              "--benchmark_filter=BM_CompensatePath/"],
                             capture_output=True, text=True, check=True).stdout
        b = json.loads(out)["benchmarks"][0]
        print(f"{'C++ compensate_path (CPU time)':45s} {b['items_per_second']:10.3e} points/s")
        print(f"target 1e5 points/s through Python: "
              f"{'met' if rows['compensate_path (q_cmd only)'] >= 1e5 else 'not met'}")


if __name__ == "__main__":
    main()
