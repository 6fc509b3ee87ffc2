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
    f.write_text("G21 G90\nG0 X0 Y0 Z0\nG2 X10 Y1 I5 J0 F100\n")
    with pytest.raises(stiff.ParseError) as e:
        stiff.read_path(f)
    assert e.value.line == 3 and e.value.column == 1 and "not on the circle" in str(e.value)


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
    (["--path", "{bad}"], "bad.nc:2:1: arc end point is not on the circle"),
    (["--path", "{csv}"], "has no wrench columns"),
    (["--path", "{csv}", "--wrench", "1,2"], "--wrench needs 3 or 6 values"),
    (["--path", "{csv}", "--wrench", "1,2,3", "--report", "x.txt"], "use a .png or .json"),
    (["--path", "/nonexistent.csv", "--wrench", "1,2,3"], "/nonexistent.csv"),
])
def test_cli_user_errors_are_one_line_and_exit_2(fits, tmp_path, extra, message):
    (tmp_path / "bad.nc").write_text("G0 X0 Y0 Z0\nG2 X1 Y2 I1 J0 F10\n")
    (tmp_path / "p.csv").write_text("x_mm,y_mm,z_mm\n450,0,-150\n")
    extra = [e.format(bad=tmp_path / "bad.nc", csv=tmp_path / "p.csv") for e in extra]
    p = run("compensate", "--robot", "rokae", "--fit", fits[2], *extra, "-o", tmp_path / "o.csv",
            cwd=tmp_path)
    assert p.returncode == 2, p.stdout + p.stderr
    assert message in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "Traceback" not in p.stderr


def _csv_rows(path):
    lines = [l for l in path.read_text().splitlines() if not l.startswith("#")]
    head = lines[0].split(",")
    return head, [dict(zip(head, l.split(","))) for l in lines[1:]]


def test_cli_unreachable_points_fail_unless_keep_going(fits, tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("x_mm,y_mm,z_mm\n450,0,-150\n5000,0,-150\n455,0,-150\n")
    out = tmp_path / "o.csv"
    args = ["compensate", "--robot", "rokae", "--fit", fits[2], "--path", path,
            "--wrench", "0,0,-100", "-o", out]
    p = run(*args)
    assert p.returncode == 3, p.stdout + p.stderr
    assert "1 of 3 points cannot be compensated: row 1 (line 3): unreachable" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and not out.exists()
    p = run(*args, "--keep-going")
    assert p.returncode == 0, p.stderr
    head, rows = _csv_rows(out)
    assert rows[1]["qcmd1_rad"] == "" and rows[1]["x_cmd_m"] == "" and rows[1]["status"] != "0"
    assert rows[0]["qcmd1_rad"] != "" and rows[2]["status"] == "0"


def test_cli_quaternions_rapids_and_recorded_options(fits, tmp_path, rokae):
    prog = tmp_path / "p.nc"
    prog.write_text("G21 G90\nG0 X0 Y0 Z20\nG1 Z0 F300\nG2 X20 Y0 I10 J0 F600\nG0 Z20\n")
    out = tmp_path / "o.csv"
    p = run("compensate", "--robot", "rokae", "--fit", fits[2], "--path", prog, "--frame",
            "400,0,-150,0,0,0", "--tool-rpy", "0,90,0", "--wrench", "0,0,-100", "-o", out)
    assert p.returncode == 0, p.stderr
    text = out.read_text()
    assert "# workpiece frame [mm, deg]: 400,0,-150,0,0,0" in text
    assert "# tool orientation [deg]: 0,90,0" in text and "--wrench 0,0,-100" in text
    head, rows = _csv_rows(out)
    # Rapid rows carry no process force; the others the constant wrench.
    assert rows[0]["rapid"] == "1" and rows[0]["fz_N"] == "0.0"
    assert rows[1]["rapid"] == "0" and float(rows[1]["fz_N"]) == -100.0
    # Quaternion columns: the same rotation as FK(q_cmd), sign fixed by qw >= 0, also at
    # ry = 90 deg where roll and yaw are not unique.
    for r in rows:
        q = np.array([float(r[f"qcmd{j}_rad"]) for j in range(1, 7)])
        rot = rokae.tool_pose(q)[:3, :3]
        w, x, y, z = (float(r[k]) for k in ("qw_cmd", "qx_cmd", "qy_cmd", "qz_cmd"))
        assert w >= 0 and abs(w * w + x * x + y * y + z * z - 1) < 1e-12
        expected = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                             [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                             [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        assert np.abs(expected - rot).max() < 1e-12
    assert "commanded correction" in p.stdout


def test_cli_orientation_error_reported_beside_position(fits, backlash_truth, root, tmp_path):
    p = run("compensate", "--robot", "rokae", "--fit", fits[3], "--path",
            root / "examples" / "paths" / "rokae_contour.csv", "--truth", backlash_truth,
            "-o", tmp_path / "c.csv", "--report", tmp_path / "r.json")
    assert p.returncode == 0, p.stderr
    assert "max rot [urad]" in p.stdout
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["fits"][0]["compensated"]["max_rot_urad"] <= rep["uncompensated"]["max_rot_urad"] + 100
    # A tolerance below what the compensation leaves makes it an error (exit 3, nothing written).
    p = run("compensate", "--robot", "rokae", "--fit", fits[2], "--path",
            root / "examples" / "paths" / "rokae_contour.csv", "--truth", backlash_truth,
            "--orientation-tolerance-urad=-1e9", "-o", tmp_path / "d.csv")
    assert p.returncode == 3 and "worsens the tool orientation" in p.stderr
    assert not (tmp_path / "d.csv").exists()
