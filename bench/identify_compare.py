"""Identification: libstiff (through the Python API over the C ABI) against the numpy/scipy peer
(bench/peers/identify_scipy.py) on the same simulated data and the same models, in one run.

    STIFF_BUILD_DIR=build .venv/bin/python bench/identify_compare.py [--sizes 10,100,1000,10000]

Prints one JSON object per line: case, N, our seconds, peer seconds, the largest relative
difference of the identified joint compliances c1..c5 between the two, and the RMS residuals.
"""
import argparse
import json
import os
import sys
import tempfile
import time

# The peer's BLAS on one thread (set before numpy loads it): on the 2-core benchmark machine,
# shared with other jobs, OpenBLAS's thread pool made the scipy fits 2-8x slower than on one
# thread (least_squares factorises a tall Jacobian every iteration). libstiff is single-threaded.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench", "peers"))
if not os.environ.get("PYTHONPATH"):  # bench/run sets it; else the source tree
    sys.path.insert(0, os.path.join(ROOT, "plugins", "python"))
import identify_scipy as peer  # noqa: E402
import stiff  # noqa: E402

ROBOT = os.path.join(ROOT, "examples", "robots", "rokae.yaml")
K = [50914, 16382, 31311, 7791.1, 5613.6, 4000]
TRUTH = """stiffness_Nm_per_rad: [50914, 16382, 31311, 7791.1, 5613.6, 4000]
effects:
  link: {c_link2_x: 4.0e-6, c_link2_y: 2.0e-6, c_link3_x: 3.0e-6}
  point_offset: {meas_x: 0.03, meas_y: -0.02, meas_z: 0.05, load_x: 0.02, load_y: 0.01, load_z: 0.08}
"""
SIGMA = 10e-6
CASES = [  # name, model, loss, truth, outliers
    ("joint, least squares", "joint", "none", None, 0.0),
    ("joint, Huber", "joint", "huber", None, 0.05),
    ("joint+link+point_offset, Huber", "joint+link+point_offset", "huber", "full", 0.05),
]


def best_time(fn, budget_s=1.0, max_reps=20):
    """Smallest wall time of repeated calls (at least one, at most max_reps or ~budget)."""
    times, out = [], None
    t_end = time.perf_counter() + budget_s
    while len(times) < max_reps and (not times or time.perf_counter() < t_end):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="10,100,1000,10000")
    args = ap.parse_args()
    robot = stiff.Robot(ROBOT)
    dh = peer.load_dh(ROBOT)
    with tempfile.TemporaryDirectory() as tmp:
        truth = os.path.join(tmp, "truth.yaml")
        with open(truth, "w") as f:
            f.write(TRUTH)
        for n in (int(s) for s in args.sizes.split(",")):
            design = stiff.random_design(robot, n, seed=11)
            for name, model, loss, tr, outl in CASES:
                kw = dict(truth=truth) if tr else dict(stiffness=K)
                data = stiff.simulate(robot, design, tracker_sigma_m=SIGMA, outlier_rate=outl,
                                      outlier_size_m=0.5e-3, seed=5, **kw)
                q, F, d = data.q, data.force, data.displacement
                M = np.zeros_like(F)
                effects = model.split("+")

                def ours():
                    return stiff.identify(robot, data, model, loss=loss)

                def theirs():
                    prob = peer.Problem(dh, q, F, M, d, effects)
                    if loss == "none":
                        th = peer.fit_joint_linear(prob)
                    else:
                        th, _ = peer.fit_huber(prob, SIGMA)
                    return prob, th

                budget = 2.0 if n >= 1000 else 1.0
                t_ours, fit = best_time(ours, budget)
                reps = 1 if n >= 10000 and loss != "none" else 5 if n >= 1000 else 20
                t_peer, (prob, th) = best_time(theirs, budget, max_reps=reps)
                c_ours = 1.0 / fit.stiffness[:5]
                c_peer = th[:5]
                diff = float(np.max(np.abs(c_peer / c_ours - 1)))
                rms_ours = float(fit.statistics.rms_m)
                r = prob.predict(np.r_[th, np.zeros(prob.n_params() - th.size)]) - d
                rms_peer = float(np.sqrt(np.mean(r ** 2)))
                print(json.dumps(dict(case=name, n=n, ours_s=t_ours, peer_s=t_peer,
                                      ratio=t_peer / t_ours, max_rel_diff_c=diff,
                                      rms_ours_um=rms_ours * 1e6, rms_peer_um=rms_peer * 1e6)),
                      flush=True)


if __name__ == "__main__":
    main()
