"""Benchmark of the stiff FMU (docs/benchmarks.md, section "FMU").

1. One output evaluation in C (fmi2SetReal of q and the wrench + fmi2GetReal of the six
   deflection outputs), and the same for the compensated targets q_cmd: bench/fmu_bench.c,
   compiled here against the FMI headers and run on the exported FMU.
2. A 1e5-step co-simulation through fmpy (simulate_fmu, CS) versus calling the C ABI
   (stiff_predict through ctypes) 1e5 times.

Usage: STIFF_BUILD_DIR=build .venv/bin/python bench/fmu_bench.py [--steps N]
"""

import argparse
import ctypes
import glob
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "fmu"))
from fmu_reference import STIFFNESS, Exporter, fit_json, load_capi, ROBOT  # noqa: E402

from fmpy import extract, read_model_description, simulate_fmu  # noqa: E402

Q = [0.3, -0.4, 0.5, 0.2, 0.9, -0.3]
W = [300.0, -200.0, 150.0, 10.0, -5.0, 8.0]


def fmi_headers():
    found = glob.glob(str(ROOT / ".venv/lib/python3*/site-packages/fmu_manipulation_toolbox/"
                          "resources/fmi"))
    if not found:
        sys.exit("FMI headers not found: pip install fmu-manipulation-toolbox==2.0")
    return found[0]


def c_eval(fmu, tmp, iterations):
    md = read_model_description(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ins = [vr[f"q{j + 1}"] for j in range(6)] + [vr[n] for n in ("fx", "fy", "fz", "mx", "my", "mz")]
    outs = [vr[n] for n in ("dx", "dy", "dz", "rx", "ry", "rz")]
    cmds = [vr[f"q_cmd{j + 1}"] for j in range(6)]
    exe = tmp / "fmu_bench"
    subprocess.run(["cc", "-O2", "-std=c99", "-D_POSIX_C_SOURCE=200809L", f"-I{fmi_headers()}",
                    f"-DIN_VR={','.join(map(str, ins))}", f"-DOUT_VR={','.join(map(str, outs))}",
                    f"-DCMD_VR={','.join(map(str, cmds))}", str(ROOT / "bench" / "fmu_bench.c"),
                    "-o", str(exe), "-ldl"], check=True)
    unzip = extract(fmu)
    out = subprocess.run([str(exe), unzip, md.guid, str(iterations)], check=True,
                         capture_output=True, text=True).stdout.split()
    return float(out[0]), float(out[1])


def fmpy_cosim(fmu, steps):
    t0 = time.perf_counter()
    res = simulate_fmu(fmu, stop_time=1.0, output_interval=1.0 / steps, output=["dx"],
                       start_values={**{f"q{j + 1}": Q[j] for j in range(6)},
                                     **dict(zip(("fx", "fy", "fz", "mx", "my", "mz"), W))})
    return time.perf_counter() - t0, len(res) - 1


def capi_loop(tmp, steps):
    lib = load_capi()
    robot = ctypes.c_void_p()
    lib.stiff_robot_load(ctypes.byref(robot), str(ROBOT).encode())
    import json

    fit_path = tmp / "fit.json"
    fit_path.write_text(json.dumps(fit_json(1.0 / STIFFNESS)))
    fit = ctypes.c_void_p()
    lib.stiff_result_read_json(ctypes.byref(fit), str(fit_path).encode())
    model = ctypes.c_void_p()
    lib.stiff_model_create.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_void_p,
                                       ctypes.c_void_p]
    assert lib.stiff_model_create(ctypes.byref(model), robot, fit) == 0, lib.stiff_last_error()
    lib.stiff_predict.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_void_p,
                                  ctypes.POINTER(ctypes.c_double), ctypes.c_size_t,
                                  ctypes.POINTER(ctypes.c_double)]
    d = (ctypes.c_double * 6)()
    q = (ctypes.c_double * 6)(*Q)
    w = (ctypes.c_double * 6)(*W)
    t0 = time.perf_counter()
    for _ in range(steps):
        lib.stiff_predict(d, model, q, 6, w)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=100000)
    ap.add_argument("--iterations", type=int, default=1000000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = pathlib.Path(d)
        fmu = Exporter(tmp).export("bench", 2)
        t_defl, t_cmd = c_eval(fmu, tmp, args.iterations)
        t_fmpy, n = fmpy_cosim(fmu, args.steps)
        t_capi = capi_loop(tmp, args.steps)
    print(f"C, one deflection evaluation (set 12 inputs, get 6 outputs): {t_defl * 1e6:.2f} us")
    print(f"C, one compensation (set 12 inputs, get q_cmd1..6):         {t_cmd * 1e6:.2f} us")
    print(f"fmpy simulate_fmu CS, {n} steps:  {t_fmpy:.2f} s ({t_fmpy / n * 1e6:.1f} us/step)")
    print(f"C ABI stiff_predict via ctypes, {args.steps} calls: {t_capi:.2f} s "
          f"({t_capi / args.steps * 1e6:.1f} us/call)")


if __name__ == "__main__":
    main()
