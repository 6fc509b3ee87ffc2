"""Time the C++ annealing (stiff_plan_benchmark) and the numpy peer (bench/peers/plan_numpy.py)
on the same pool in the same run; print swaps/s and the ratio.

    .venv/bin/python bench/plan_compare.py build-plan/bench/stiff_plan_benchmark [pool_size]
"""
import json
import os
import subprocess
import sys
import tempfile

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
            [exe, f"--benchmark_filter=BM_AnnealSwaps/{size}$", "--benchmark_format=json",
             "--benchmark_repetitions=3", "--benchmark_report_aggregates_only=true"],
            check=True, capture_output=True, text=True).stdout
        runs = json.loads(out)["benchmarks"]
        cpp = max(r["swaps_per_s"] for r in runs if r.get("aggregate_name") in ("median", "mean", None))
        cpp_kappa = runs[0]["kappa_a"]
        py_rate, py_kappa, dt = plan_numpy.swaps_per_second(pool, iterations=5000)
        print(f"pool {size:>6}: C++ {cpp:.4g} swaps/s (kappa_a {cpp_kappa:.4f}, 1e5 iterations) | "
              f"numpy {py_rate:.4g} swaps/s (kappa_a {py_kappa:.4f}, 5000 iterations, {dt:.2f} s) | "
              f"ratio {cpp / py_rate:.0f}x")


if __name__ == "__main__":
    main()
