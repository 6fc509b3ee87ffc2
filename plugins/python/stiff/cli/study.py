"""stiff study: Monte-Carlo studies of the planning criteria on the virtual robot."""
from __future__ import annotations

import os
from pathlib import Path

from .common import Formatter, ProgressBar, data_dir, robot_path

EXAMPLE = """example:
  stiff study paper                       # 500 trials, writes paper-study.md + paper-study/*.png
  stiff study paper --trials 20 -o /tmp/study.md
  examples/paper_study/run.sh             # regenerates docs/paper-study.md

Each trial draws a new candidate pool on the ROKAE twin, chooses 10 poses with loads by every
criterion (kappa_a by the paper's annealing, kappa_j, d_opt, a_opt, e_opt, task), random sets
and the paper's two printed sets (q6 = 0), simulates the measurements under three error models
(realistic; purely relative; realistic with outliers, fitted with the Huber loss), identifies
the joint stiffness and validates at 20 random loaded poses. Tables carry 95% confidence
intervals; the paper's figures stand beside ours. 500 trials take a few minutes on 2 cores."""


def register(sub):
    p = sub.add_parser("study", help="Monte-Carlo study of the paper's claim (planning criteria)",
                       description=__doc__, epilog=EXAMPLE, formatter_class=Formatter)
    p.add_argument("which", choices=["paper"], help="the study to run (paper: the kappa_F^-1(A) criterion of Jiang & Fang 2023 against D-optimal designs, docs/paper-study.md)")
    p.add_argument("--trials", "-n", type=int, default=500, help="Monte-Carlo trials (default 500)")
    p.add_argument("--seed", type=int, default=1, help="seed of the whole study (default 1)")
    p.add_argument("--jobs", "-j", type=int, default=min(2, os.cpu_count() or 1),
                   help="worker processes (default 2)")
    p.add_argument("--robot", "-r", default="rokae", help="robot (default: the built-in rokae)")
    p.add_argument("--iterations", type=int, default=20000,
                   help="annealing iterations per set (default 2e4)")
    p.add_argument("--pool-poses", type=int, default=200, help="candidate poses (default 200)")
    p.add_argument("--pool-loads", type=int, default=50, help="candidate loads (default 50)")
    p.add_argument("-o", "--output", default="paper-study.md", help="markdown report to write")
    p.add_argument("--plots", help="folder of the PNG plots (default: the report's name "
                   "without .md)")
    p.add_argument("--save", help="also pickle the raw trial results here (to re-render)")
    p.add_argument("--load", help="re-render the report from results saved with --save "
                   "(no trials are run)")
    p.set_defaults(func=run)


def run(args):
    from . import UserError
    from ..study import StudyConfig, run_study, write_report

    if args.trials < 2:
        raise UserError("--trials must be at least 2 (confidence intervals need 2 trials)")
    out = Path(args.output)
    if out.parent and not out.parent.exists():
        raise UserError(f"{out.parent}: no such folder")
    cfg = StudyConfig(trials=args.trials, seed=args.seed, jobs=max(1, args.jobs),
                      robot_path=robot_path(args.robot), paper_dir=str(data_dir() / "paper"),
                      annealing_iterations=args.iterations, pool_poses=args.pool_poses,
                      pool_loads=args.pool_loads)
    import pickle

    if args.load:
        with open(args.load, "rb") as f:
            study = pickle.load(f)
        cfg = study["config"]
    else:
        with ProgressBar("study") as bar:
            try:
                study = run_study(cfg, progress=lambda done, total: bar.update(
                    done, total, f"{done}/{total} trials"))
            except KeyboardInterrupt:
                raise UserError("stopped (Ctrl-C); nothing written")
    if args.save:
        with open(args.save, "wb") as f:
            pickle.dump(study, f)
    cmd = f"stiff study paper --trials {cfg.trials} --seed {cfg.seed}"
    s = write_report(study, out, args.plots, command=cmd)
    print(f"{cfg.trials} trials in {study['seconds']:.0f} s; wrote {out}")
    for v, ranked in s["ranking"].items():
        best = ranked[0]
        m = s["variants"][v][best]["mean_err"]
        print(f"  {v:<10} best criterion {best} (mean error {m[0]:.3g} um); "
              f"kappa_a {s['variants'][v]['kappa_a']['mean_err'][0]:.3g} um, "
              f"kappa_j {s['variants'][v]['kappa_j']['mean_err'][0]:.3g} um")
    return 0
