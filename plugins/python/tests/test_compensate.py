"""Compensation: Python API (IK, paths, compensation, truth deviation) and `stiff compensate`."""
import json
import subprocess
import sys

import numpy as np
import pytest

import stiff
from stiff import compensate as cp

STIFF = [sys.executable, "-m", "stiff.cli"]


@pytest.fixture(scope="module")
def rokae(rokae_path):
    return stiff.Robot(rokae_path)


@pytest.fixture(scope="module")
def backlash_truth(root):
    return str(root / "examples" / "truths" / "rokae_backlash.yaml")


@pytest.fixture(scope="module")
def fits(rokae, backlash_truth, tmp_path_factory):
    """Joint-only and joint+backlash fits of noise-free data from the backlash truth."""
    design = stiff.random_design(rokae, count=60, seed=4)
    data = stiff.simulate(rokae, design, truth=backlash_truth, tracker_sigma_m=0.0)
    d = tmp_path_factory.mktemp("fits")
    joint = stiff.identify(rokae, data)
    full = stiff.identify(rokae, data, model="joint+backlash")
    joint.write(d / "joint.json")
    full.write(d / "full.json")
    return joint, full, d / "joint.json", d / "full.json"


def test_ik_all_branches_round_trip(rokae):
    assert cp.ik_is_analytic(rokae)
    rng = np.random.default_rng(1)
    lo, hi = rokae.limits
    worst = 0.0
    for _ in range(50):
        q = lo * 0.9 + (hi - lo) * 0.9 * rng.random(6) * 1.0
        q = np.clip(q, lo, hi)
        pose = rokae.tool_pose(q)
        sols = stiff.inverse_kinematics(rokae, pose, q)
        assert sols.shape[1] == 6 and 1 <= sols.shape[0] <= 8
        assert np.abs(sols[0] - q).max() < 1e-7  # nearest the seed first: q itself
        for s in sols:
            worst = max(worst, np.abs(rokae.tool_pose(s) - pose).max())
    assert worst < 1e-10


def test_ik_unreachable_is_a_clear_error(rokae):
    pose = np.eye(4)
    pose[0, 3] = 5.0
    with pytest.raises(stiff.NumericalError, match="unreachable"):
        stiff.inverse_kinematics(rokae, pose)
    q, status = stiff.inverse_kinematics(rokae, np.stack([rokae.tool_pose(np.full(6, 0.2)), pose]))
    assert np.isfinite(q).all() and status[1] & cp.POINT_UNREACHABLE
    assert cp.status_text(status[1]) == "unreachable"


def test_read_path_csv_and_gcode(root):
    p = stiff.read_path(root / "examples" / "paths" / "rokae_contour.csv")
    assert len(p) == 335 and p.wrench.shape == (335, 6) and p.lines[0] == 6
    g = stiff.read_path(root / "examples" / "paths" / "pocket.nc",
                        frame=[0.37, -0.04, -0.15, 0, 0, 0], segment_m=0.005)
    assert g.wrench is None and len(g) > 100
    assert np.allclose(g.poses[:, 2, 2], -1.0)  # tool pointing down


def test_gcode_arc_error_names_the_line(tmp_path):
    f = tmp_path / "arc.nc"
    f.write_text("G21 G90\nG0 X0 Y0 Z0\nG2 X10 Y0 I5 J0 F100\n")
    with pytest.raises(stiff.ParseError) as e:
        stiff.read_path(f)
    assert e.value.line == 3 and e.value.column == 1 and "arcs (G2)" in str(e.value)


def test_compensation_reaches_the_nominal_path_on_the_truth(rokae, fits, backlash_truth, root):
    joint, full, *_ = fits
    path = stiff.read_path(root / "examples" / "paths" / "rokae_contour.csv")
    out = {}
    for name, fit in (("joint", joint), ("full", full)):
        res = stiff.compensate_path(stiff.Model(rokae, fit), path.poses, path.wrench)
        assert not res.problems()
        # The compensated Cartesian targets are FK(q_cmd).
        assert np.allclose(res.pose_cmd[7], rokae.tool_pose(res.q_cmd[7]), atol=1e-14)
        before = cp.truth_deviation(rokae, backlash_truth, res.q_nominal, path.poses, path.wrench)
        after = cp.truth_deviation(rokae, backlash_truth, res.q_cmd, path.poses, path.wrench)
        out[name] = (np.linalg.norm(before[:, :3], axis=1), np.linalg.norm(after[:, :3], axis=1))
    b, a_full = out["full"]
    assert b.max() > 1e-3
    assert (a_full <= 0.01 * b).all()
    assert out["joint"][1].max() > 10 * a_full.max()  # the missing effect matters


def test_compensate_pose_and_constant_wrench(rokae, fits):
    model = stiff.Model(rokae, fits[0])
    q = np.array([0.1, 0.4, -0.5, 0.3, 0.9, -0.4])
    w = np.array([50.0, -30.0, -100.0])
    q_cmd = cp.compensate_pose(model, q, w)
    d = model.predict(q_cmd, w)
    assert np.abs(rokae.tool_pose(q_cmd)[:3, 3] + d[:3] - rokae.tool_pose(q)[:3, 3]).max() < 1e-9
    res = stiff.compensate_path(model, rokae.tool_pose(q)[None], w, q_start=q)
    assert np.abs(res.q_cmd[0] - q_cmd).max() < 1e-9
    with pytest.raises(ValueError):
        stiff.compensate_path(model, np.stack([np.eye(4)] * 3), np.zeros((2, 6)))


def test_numerical_ik_on_ur5(root):
    ur5 = stiff.Robot(root / "examples" / "robots" / "ur5.urdf")
    assert not cp.ik_is_analytic(ur5)
    q = np.array([0.3, -1.0, 1.2, -0.5, 1.1, 0.2])
    sols = stiff.inverse_kinematics(ur5, ur5.tool_pose(q), q)
    assert np.abs(sols[0] - q).max() < 1e-7


def run(*args, cwd=None):
    return subprocess.run(STIFF + [str(a) for a in args], capture_output=True, text=True, cwd=cwd)


def test_cli_end_to_end(fits, backlash_truth, root, tmp_path):
    _, _, joint_json, full_json = fits
    p = run("compensate", "--robot", "rokae", "--fit", joint_json, "--compare-fit", full_json,
            "--path", root / "examples" / "paths" / "rokae_contour.csv", "--truth",
            backlash_truth, "-o", tmp_path / "c.csv", "--report", tmp_path / "r.json",
            "--report", tmp_path / "r.png")
    assert p.returncode == 0, p.stderr
    assert "uncompensated" in p.stdout and "joint+backlash" in p.stdout
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["points"] == 335 and rep["fits"][1]["ratio"] < 0.01 < rep["fits"][0]["ratio"]
    assert (tmp_path / "r.png").stat().st_size > 10000
    lines = [l for l in (tmp_path / "c.csv").read_text().splitlines() if not l.startswith("#")]
    head = lines[0].split(",")
    assert "qcmd6_rad" in head and "x_cmd_m" in head and head[-1] == "status"
    assert len(lines) == 336
    # G-code with a frame and a constant wrench.
    p = run("compensate", "--robot", "rokae", "--fit", joint_json, "--path",
            root / "examples" / "paths" / "pocket.nc", "--frame", "370,-40,-150,0,0,0",
            "--wrench", "0,0,-100", "--segment", "2", "-o", tmp_path / "g.csv")
    assert p.returncode == 0, p.stderr
    assert "--wrench" not in p.stdout


def test_cli_help_has_a_worked_example():
    p = run("compensate", "--help")
    assert p.returncode == 0 and "worked example" in p.stdout and "--compare-fit" in p.stdout


@pytest.mark.parametrize("extra, message", [
    (["--path", "{bad}"], "bad.nc:2:1: arcs (G2)"),
    (["--path", "{csv}"], "has no wrench columns"),
    (["--path", "{csv}", "--wrench", "1,2"], "--wrench needs 3 or 6 values"),
    (["--path", "{csv}", "--wrench", "1,2,3", "--report", "x.txt"], "use a .png or .json"),
    (["--path", "/nonexistent.csv", "--wrench", "1,2,3"], "/nonexistent.csv"),
])
def test_cli_user_errors_are_one_line_and_exit_2(fits, tmp_path, extra, message):
    (tmp_path / "bad.nc").write_text("G0 X0 Y0 Z0\nG2 X1 Y1 I1 J0 F10\n")
    (tmp_path / "p.csv").write_text("x_mm,y_mm,z_mm\n450,0,-150\n")
    extra = [e.format(bad=tmp_path / "bad.nc", csv=tmp_path / "p.csv") for e in extra]
    p = run("compensate", "--robot", "rokae", "--fit", fits[2], *extra, "-o", tmp_path / "o.csv",
            cwd=tmp_path)
    assert p.returncode == 2, p.stdout + p.stderr
    assert message in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "Traceback" not in p.stderr
