"""Absolute (geometric) calibration from Python and the command line: a virtual UR5 measured
in a tracker frame away from its base, with an unknown target offset."""
import json
import subprocess
import sys

import numpy as np
import pytest

import stiff
from stiff.compensate import rotation_from_vector, rotation_vector_angle_between

STIFF = [sys.executable, "-m", "stiff.cli"]


def rot(w):
    """Rotation matrix of a rotation vector (Rodrigues)."""
    a = np.linalg.norm(w)
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]) / a
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def write_absolute(path, robot, rows, seed, sigma=20e-6, tool=(0.01, -0.02, 0.08),
                   frame=((0.1, -0.2, 2.5), (1.8, -0.7, 0.2)), first=0):
    rng = np.random.default_rng(seed)
    r, t = rot(np.array(frame[0])), np.array(frame[1])
    lines = ["id,session," + ",".join(f"q{j + 1}_rad" for j in range(robot.dof)) +
             ",px_m,py_m,pz_m"]
    for i in range(rows):
        q = rng.uniform(-2.8, 2.8, robot.dof)
        pose = robot.tool_pose(q)
        p = r @ (pose[:3, :3] @ np.array(tool) + pose[:3, 3]) + t + rng.normal(0, sigma, 3)
        lines.append(f"p{first + i},T1," + ",".join(repr(float(v)) for v in q) + "," +
                     ",".join(repr(float(v)) for v in p))
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture()
def ur5(root):
    return stiff.Robot(str(root / "examples" / "robots" / "ur5.urdf"))


def test_identify_and_predict_absolute(tmp_path, ur5):
    calib, valid = tmp_path / "calib.csv", tmp_path / "valid.csv"
    write_absolute(calib, ur5, 60, seed=1)
    write_absolute(valid, ur5, 20, seed=2, sigma=0.0, first=100)
    data = stiff.Dataset.read(calib, ur5)
    assert data.absolute.all() and data.position.shape == (60, 3)
    fit = stiff.identify(ur5, data, model="registration+tool")
    values = {p["name"]: p["value"] for p in fit.json["parameters"]}
    # The tool offset the data were made with, to a few noise sigmas.
    assert abs(values["r_z"] - 0.08) < 2e-5 and abs(values["r_x"] - 0.01) < 2e-5
    assert fit.json["sessions"] == ["T1"]
    pred = stiff.Model(ur5, fit).predict_dataset(stiff.Dataset.read(valid, ur5))
    err = np.linalg.norm(pred - stiff.Dataset.read(valid, ur5).position, axis=1)
    assert err.max() < 6 * 20e-6


def test_cli_identify_predict_absolute(tmp_path, ur5, root):
    calib, valid = tmp_path / "calib.csv", tmp_path / "valid.csv"
    write_absolute(calib, ur5, 60, seed=3)
    write_absolute(valid, ur5, 20, seed=4, first=100)
    urdf = root / "examples" / "robots" / "ur5.urdf"
    p = subprocess.run(STIFF + ["identify", "--robot", str(urdf), "--data", str(calib),
                                "--model", "registration+tool+joint_offset",
                                "-o", str(tmp_path / "fit.json")], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    fit = json.loads((tmp_path / "fit.json").read_text())
    assert any(q["name"] == "dq1" and not q["identified"] for q in fit["parameters"])
    p = subprocess.run(STIFF + ["predict", "--robot", str(urdf), "--fit", str(tmp_path / "fit.json"),
                                "--data", str(valid), "-o", str(tmp_path / "pred.csv")],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "absolute position error on 20 rows" in p.stdout
    assert (tmp_path / "pred.csv").read_text().startswith("id,absolute,x_m,y_m,z_m")


def test_absolute_row_without_registration_is_refused(tmp_path, ur5):
    calib = tmp_path / "calib.csv"
    write_absolute(calib, ur5, 20, seed=5)
    with pytest.raises(stiff.StiffError, match="metres away"):
        stiff.identify(ur5, stiff.Dataset.read(calib, ur5), model="tool")


def write_six_d(path, robot, rows, seed, sigma=20e-6, probe=(0.3, -1.1, 0.6), first=0):
    """6-D rows: positions as write_absolute (tool at the flange origin) and the orientation of
    a probe turned by `probe` on the flange, with sigma [rad] of noise per axis (1 m per rad)."""
    rng = np.random.default_rng(seed)
    r, t = rot(np.array((0.1, -0.2, 2.5))), np.array((1.8, -0.7, 0.2))
    lines = ["# euler: xyz", "id,session," + ",".join(f"q{j + 1}_rad" for j in range(robot.dof))
             + ",px_m,py_m,pz_m,a_rad,b_rad,c_rad"]
    for i in range(rows):
        q = rng.uniform(-2.8, 2.8, robot.dof)
        pose = robot.tool_pose(q)
        p = r @ pose[:3, 3] + t + rng.normal(0, sigma, 3)
        m = rotation_from_vector(rng.normal(0, sigma, 3))[0] @ r @ pose[:3, :3] @ rot(np.array(probe))
        # R = Rx(a) Ry(b) Rz(c)
        e = (np.arctan2(-m[1, 2], m[2, 2]), np.arcsin(m[0, 2]), np.arctan2(-m[0, 1], m[0, 0]))
        lines.append(f"p{first + i},T1," + ",".join(repr(float(v)) for v in (*q, *p, *e)))
    path.write_text("\n".join(lines) + "\n")


def test_six_d_data_identify_the_probe_frame(tmp_path, ur5):
    calib, valid = tmp_path / "calib.csv", tmp_path / "valid.csv"
    write_six_d(calib, ur5, 60, seed=11)
    write_six_d(valid, ur5, 20, seed=12, sigma=0.0, first=100)
    data = stiff.Dataset.read(calib, ur5)
    assert data.orientation.shape == (60, 3)
    model = "registration+tool+tool_orientation"
    fit = stiff.identify(ur5, data, model=model)
    s = fit.statistics
    assert s.oriented_rows == 60
    # At the noise (20 urad per axis), and weighed about as made (1 m per rad).
    assert 0.6 * 20e-6 < s.orientation_rms_rad < 1.4 * 20e-6, s
    assert 0.5 < s.orientation_length_m < 2.0, s
    w = np.array([p["value"] for p in fit.json["parameters"] if p["effect"] == "tool_orientation"])
    assert np.abs(w - (0.3, -1.1, 0.6)).max() < 1e-4, w
    assert fit.orientation_residuals.shape == (60, 3)
    v = stiff.Dataset.read(valid, ur5)
    angle = rotation_vector_angle_between(v.orientation, stiff.Model(ur5, fit).predict_orientation(v))
    assert angle.max() < 6 * 20e-6, angle.max()
    # Positions alone: the probe's frame is invisible, held and named.
    pos = stiff.identify(ur5, data, model=model, use_orientation=False)
    assert pos.statistics.oriented_rows == 0 and pos.orientation_residuals is None
    assert not any(p["identified"] for p in pos.json["parameters"]
                   if p["effect"] == "tool_orientation")
    assert any(w.startswith("tool_orientation.w_x is not identifiable") for w in pos.warnings)
    with pytest.raises(stiff.StiffError, match="orientation_length_m"):
        stiff.identify(ur5, data, model=model, orientation_length_m=-1.0)
