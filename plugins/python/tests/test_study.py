"""The Monte-Carlo study of the paper's claim (`stiff study paper`) and its statistics."""
import math
import subprocess
import sys

import numpy as np
import pytest

from stiff import study

STIFF = [sys.executable, "-m", "stiff.cli"]


def test_mean_ci_on_known_data():
    m, lo, hi = study.mean_ci([1, 2, 3, 4, 5])
    # t(0.975, 4) = 2.776445; s = sqrt(2.5); half width = 2.776445 * sqrt(2.5 / 5)
    assert m == 3.0
    assert hi - m == pytest.approx(2.776445 * math.sqrt(0.5), rel=1e-6)
    assert m - lo == pytest.approx(hi - m)
    assert study.mean_ci([1, 2, 3, np.nan, 4, 5]) == (m, lo, hi)  # non-finite values dropped
    m1, lo1, hi1 = study.mean_ci([7.0])
    assert m1 == 7.0 and math.isnan(lo1) and math.isnan(hi1)


def test_t_quantile_matches_tables():
    assert study.t_quantile(0.975, 4) == pytest.approx(2.776445, rel=1e-6)
    assert study.t_quantile(0.975, 1000) == pytest.approx(1.962339, rel=1e-5)


def test_bootstrap_and_reduction_intervals():
    rng = np.random.default_rng(3)
    b = rng.uniform(1, 2, 400)
    assert study.reduction_ci(0.5 * b, b) == pytest.approx((50.0, 50.0, 50.0))
    r, lo, hi = study.reduction_ci(b * rng.uniform(0.6, 0.8, b.size), b)
    assert lo < r < hi and 20 < lo and hi < 40
    med, lo, hi = study.bootstrap_ci(np.arange(101.0), np.median)
    assert med == 50.0 and lo < 50 < hi and hi - lo < 30
    # A normal sample: the bootstrap interval of the mean is close to the t interval.
    x = rng.normal(10, 2, 500)
    bm = study.bootstrap_ci(x, np.mean)
    tm = study.mean_ci(x)
    assert bm[0] == pytest.approx(tm[0])
    assert bm[1] == pytest.approx(tm[1], abs=0.05) and bm[2] == pytest.approx(tm[2], abs=0.05)


def _tables(text):
    """The validation tables (the planning-time column and the header vary between runs)."""
    start = text.index("## The paper's comparison")
    return text[start:text.index("## Criterion values")]


def test_tiny_study_through_the_cli(tmp_path):
    out = []
    for k in range(2):
        md = tmp_path / f"study{k}.md"
        p = subprocess.run(STIFF + ["study", "paper", "--trials", "4", "--jobs", "2", "--seed", "7",
                                    "--iterations", "2000", "-o", str(md)],
                           capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        assert "4 trials" in p.stdout and "best criterion" in p.stdout
        out.append(md.read_text())
    text = out[0]
    for section in ("## Setup", "## The paper's comparison", "## Validation errors, `realistic`",
                    "## Validation errors, `relative`", "## Validation errors, `outliers`",
                    "## Identified stiffness per joint", "## Criterion values reached",
                    "## Findings", "## Why"):
        assert section in text, section
    for design in ("kappa_a", "kappa_j", "d_opt", "a_opt", "e_opt", "task", "random", "paper_a",
                   "paper_j"):
        assert f"| `{design}` |" in text, design
    assert "| mean error | 29.59 |" in text and "| variance y | 42.21 |" in text
    assert (tmp_path / "study0" / "error_by_design.png").stat().st_size > 1000
    assert _tables(out[0]) == _tables(out[1])  # same seed, same numbers


def test_study_rejects_one_trial(tmp_path):
    p = subprocess.run(STIFF + ["study", "paper", "--trials", "1", "-o", str(tmp_path / "s.md")],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "at least 2" in p.stderr
