"""Time the C++ annealing (stiff_plan_benchmark) and the numpy peer (bench/peers/plan_numpy.py)
on the same pool in the same run; print swaps/s and the ratio.

    .venv/bin/python bench/plan_compare.py build-plan/bench/stiff_plan_benchmark [pool_size ...]

Both sides are timed in CPU time of the process (Google Benchmark's rate counters use CPU time;
the peer uses time.process_time), so that a loaded machine does not favour either side; the
peer's wall-clock rate is printed too. OpenBLAS is held to one thread: the peer's 5 x 5 products
never use more, and idle BLAS threads would otherwise count as process CPU time.
"""
import json
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "peers"))
import plan_numpy  # noqa: E402

POSES = {1000: 100, 10000: 200, 100000: 1000}  # as in plan_benchmark.cpp


def main():
    exe = sys.argv[1]
    sizes = [int(a) for a in sys.argv[2:]] or [1000, 10000, 100000]
    for size in sizes:
        poses = POSES[size]
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "pool.bin")
            subprocess.run([exe, "--dump-pool", path, str(poses), str(size // poses)], check=True)
            pool = plan_numpy.load_pool(path)
        out = subprocess.run(
            [exe, f"--benchmark_filter=BM_(AnnealSwaps|AnnealSwapsClassicalT0|PlanToFinalSet)/{size}$",
             "--benchmark_format=json", "--benchmark_repetitions=3",
             "--benchmark_report_aggregates_only=true"],
            check=True, capture_output=True, text=True).stdout
        runs = [r for r in json.loads(out)["benchmarks"] if r.get("aggregate_name") == "median"]
        swaps = next(r for r in runs if r["name"].startswith("BM_AnnealSwaps/"))
        hot = next(r for r in runs if r["name"].startswith("BM_AnnealSwapsClassicalT0/"))
        plan = next(r for r in runs if r["name"].startswith("BM_PlanToFinalSet"))
        cpp, cpp_kappa = swaps["swaps_per_s"], swaps["kappa_a"]
        unit = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[plan.get("time_unit", "ns")]
        cpu0, wall0 = time.process_time(), time.perf_counter()
        _, py_kappa = plan_numpy.anneal(pool, 10, 5000, 1)
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        py_rate, py_wall_rate = 5000 / cpu, 5000 / wall
        print(f"pool {size:>6}: C++ {cpp:.4g} swaps/s (kappa_a {cpp_kappa:.4f}, 1e5 iterations, "
              f"CPU time, median of 3) | numpy {py_rate:.4g} swaps/s (kappa_a {py_kappa:.4f}, "
              f"5000 iterations, CPU {cpu:.2f} s; wall {py_wall_rate:.4g} swaps/s) | "
              f"ratio {cpp / py_rate:.0f}x (CPU time) | C++ 1e5-iteration plan "
              f"{plan['cpu_time'] * unit:.1f} ms CPU / {plan['real_time'] * unit:.1f} ms wall | "
              f"classical T0 (accepted {hot['accepted']:.1%}): C++ {hot['swaps_per_s']:.4g} swaps/s, "
              f"ratio {hot['swaps_per_s'] / py_rate:.0f}x")

if __name__ == "__main__":
    main()
