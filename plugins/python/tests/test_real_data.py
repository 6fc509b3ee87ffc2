"""stiff's geometric calibration on the shipped UR5 data against the independent reference
(bench/peers/absolute_ref.py, docs/real-data.md). Skipped while this build of stiff has no
geometric calibration effects."""
import csv
import subprocess
import sys

import numpy as np
import pytest

import stiff

GEOMETRY = ["registration", "tool", "joint_offset", "kinematic"]

# The reference's figure on the 20 random poses after calibrating on the 1000 grid poses
# (docs/real-data.md), and the resolution of a 20-pose mean: 1.96 s / sqrt(20) with s ~ 0.03 mm.
REFERENCE_MEAN_MM, RESOLUTION_MM, MAX_MM = 0.1005, 0.013, 0.173


def _positions_mm(path):
    rows = [ln for ln in open(path).read().splitlines() if ln and not ln.startswith("#")]
    r = list(csv.DictReader(rows))
    return [x["id"] for x in r], np.array([[float(x[k]) for k in ("px_mm", "py_mm", "pz_mm")]
                                           for x in r])


def test_ur5_geometry_validation_matches_reference(root, tmp_path):
    if not set(GEOMETRY) <= set(stiff.effects()):
        pytest.skip("this build of stiff has no geometric calibration effects")
    grid = root / "examples/real/ur5/ur5_grid.csv"
    test = root / "examples/real/ur5/ur5_random.csv"
    fit, pred = tmp_path / "fit.json", tmp_path / "pred.csv"
    cli = [sys.executable, "-m", "stiff.cli"]
    for cmd in (["identify", "--robot", "ur5", "--data", str(grid), "--model", "+".join(GEOMETRY),
                 "-o", str(fit)],
                ["predict", "--robot", "ur5", "--fit", str(fit), "--data", str(test),
                 "-o", str(pred)]):
        r = subprocess.run(cli + cmd, capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    ids, measured = _positions_mm(test)
    with open(pred) as f:
        P = {x["id"]: [float(x[k]) * 1e3 for k in ("x_m", "y_m", "z_m")] for x in csv.DictReader(f)}
    e = np.linalg.norm(np.array([P[i] for i in ids]) - measured, axis=1)
    assert e.mean() <= REFERENCE_MEAN_MM + RESOLUTION_MM, e.mean()
    assert e.max() <= MAX_MM
