"""Quality side of the planning benchmark: the best criterion value each optimizer reaches within
a fixed time budget, on the same pool (ROKAE, N = 10, q6 = 0, 500 poses x 100 loads, seed 1).

    STIFF_BUILD_DIR=build .venv/bin/python bench/plan_quality.py [--budgets 0.02,0.1,0.5]

Annealing: the iteration count is calibrated so that one run fills the budget. Exchange: runs to
convergence (no knob); reported with its own time, and marked over budget when slower.
annealing+exchange / +refine: annealing calibrated to half the budget, then the exchange
(and the NLopt refinement). Prints one JSON object per line.
"""
import argparse
import json
import math
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if not os.environ.get("PYTHONPATH"):  # bench/run sets it; else the source tree
    sys.path.insert(0, os.path.join(ROOT, "plugins", "python"))
import stiff  # noqa: E402

Q_FIXED = [math.nan] * 5 + [0.0]


def run(robot, criterion, optimizers, iterations):
    t0 = time.perf_counter()
    p = stiff.plan(robot, 10, criterion, seed=1, q_fixed=Q_FIXED, optimizers=optimizers,
                   annealing_iterations=max(1, int(iterations)))
    return time.perf_counter() - t0, p.value


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--budgets", default="0.02,0.1,0.5")
    ap.add_argument("--criteria", default="kappa_a,d_opt")
    args = ap.parse_args()
    robot = stiff.Robot(os.path.join(ROOT, "examples", "robots", "rokae.yaml"))
    for crit in args.criteria.split(","):
        # Pool construction time (seconds) at 1 iteration, and the annealing cost per iteration.
        base, _ = min(run(robot, crit, ("annealing",), 1) for _ in range(3))
        t_big, _ = run(robot, crit, ("annealing",), 100000)
        per_it = max(t_big - base, 1e-9) / 100000
        t_ex, v_ex = run(robot, crit, ("exchange",), 1)
        for b in (float(x) for x in args.budgets.split(",")):
            it = max(1.0, (b - base) / per_it)
            t, v = run(robot, crit, ("annealing",), it)
            rows = [("annealing", t, v, int(it))]
            rows.append(("exchange", t_ex, v_ex, 0))
            it2 = max(1.0, (b / 2 - base) / per_it)
            t, v = run(robot, crit, ("annealing", "exchange"), it2)
            rows.append(("annealing+exchange", t, v, int(it2)))
            t, v = run(robot, crit, ("annealing", "refine"), it2)
            rows.append(("annealing+refine", t, v, int(it2)))
            for name, t, v, iters in rows:
                print(json.dumps(dict(criterion=crit, budget_s=b, optimizer=name, seconds=t,
                                      value=v, iterations=iters, over_budget=t > 1.2 * b)),
                      flush=True)


if __name__ == "__main__":
    main()
