"""URDF export of the calibrated robot (`Robot.to_urdf`, `Robot.save`, `stiff robot show --urdf`):
the written URDF, read back by stiff and, independently, parsed with xml.etree and evaluated with
numpy from the URDF semantics (origin rpy = Rz(yaw) Ry(pitch) Rx(roll) about fixed axes, then a
rotation about the joint axis), gives the calibrated robot's forward kinematics to 1e-9 m and
1e-9 rad: for the UR5 calibrated on the shipped tracker data (the registration as the world
link), the UR10 (standard DH) calibrated on its series C, and a 7-joint arm."""
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import stiff

GEOMETRY = "registration+tool+joint_offset+kinematic"


@pytest.fixture(scope="module")
def ur5_fit(root):
    robot = stiff.Robot("ur5")
    grid = stiff.Dataset.read(root / "examples/real/ur5/ur5_grid.csv", robot)
    return robot, stiff.identify(robot, grid, model=GEOMETRY)


@pytest.fixture(scope="module")
def ur10_fit(root):
    robot = stiff.Robot("ur10")
    data = stiff.Dataset.read(root / "examples/real/ur10/ur10_C_random_poses.csv", robot)
    return robot, stiff.identify(robot, data, model=GEOMETRY)


# ---------------------------------------------------------------- independent URDF kinematics

def _vec(text):
    return np.array([float(x) for x in text.split()])


def _origin(joint):
    o = joint.find("origin")
    xyz = _vec(o.get("xyz", "0 0 0")) if o is not None else np.zeros(3)
    r, p, y = _vec(o.get("rpy", "0 0 0")) if o is not None else np.zeros(3)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    t = np.eye(4)
    t[:3, :3] = rz @ ry @ rx
    t[:3, 3] = xyz
    return t


def _axis_rotation(axis, angle):
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.eye(4)
    t[:3, :3] = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    return t


def urdf_fk(text, q, base, tip):
    """Pose of `tip` in `base` at joint values q (moving joints in chain order)."""
    root = ET.fromstring(text)
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    chain = []
    link = tip
    while link != base:
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link")
    chain.reverse()
    t, k = np.eye(4), 0
    for j in chain:
        t = t @ _origin(j)
        if j.get("type") in ("revolute", "continuous"):
            t = t @ _axis_rotation(_vec(j.find("axis").get("xyz")), q[k])
            k += 1
    assert k == len(q)
    return t


def _angle(a, b):
    """Rotation angle between two orientations, accurate near zero (|R_a - R_b|_F =
    2 sqrt(2) sin(angle / 2); arccos of the trace would lose half the digits)."""
    d = np.linalg.norm(a[:3, :3] - b[:3, :3])
    return float(2 * np.arcsin(min(1.0, d / (2 * np.sqrt(2)))))


def _random_q(robot, count, seed):
    lo, hi = robot.limits
    return np.random.default_rng(seed).uniform(lo, hi, (count, robot.dof))


def _same_fk(expected, poses_got, tol=1e-9):
    for e, g in zip(expected, poses_got):
        assert np.linalg.norm(e[:3, 3] - g[:3, 3]) < tol
        assert _angle(e, g) < tol


# ---------------------------------------------------------------- tests

def test_calibrated_ur5_urdf_reloads_with_the_calibrated_kinematics(ur5_fit, root, tmp_path):
    robot, fit = ur5_fit
    cal = robot.calibrated(fit)
    path = tmp_path / "ur5_cal.urdf"
    cal.save(path, world=fit.registration())
    q = _random_q(robot, 50, 1)
    # Read back by stiff from base_link to the measured point: the calibrated robot.
    again = stiff.Robot(path, tip="tcp")
    _same_fk(cal.tool_pose(q), again.tool_pose(q))
    assert np.abs(again.limits[0] - cal.limits[0]).max() == 0
    # From the world link: the calibrated robot in the tracker frame, i.e. the fit's own
    # prediction of the tracker readings.
    placed = stiff.Robot(path, base="world", tip="tcp")
    test = stiff.Dataset.read(root / "examples/real/ur5/ur5_random.csv", robot)
    predicted = stiff.Model(robot, fit).predict_dataset(test)
    assert np.abs(placed.tool_pose(test.q)[:, :3, 3] - predicted).max() < 1e-9
    # The calibration is in it: the nominal robot misses by tenths of a millimetre.
    assert np.abs(robot.tool_pose(q)[:, :3, 3] - cal.tool_pose(q)[:, :3, 3]).max() > 1e-4


@pytest.mark.parametrize("which", ["ur5", "ur10", "iiwa14", "puma560"])
def test_exported_urdf_evaluated_independently(which, ur5_fit, ur10_fit, root):
    """numpy forward kinematics from the XML alone, against stiff's robot."""
    if which == "ur5":
        robot, fit = ur5_fit
        robot, world = robot.calibrated(fit), fit.registration()
    elif which == "ur10":  # standard DH, calibrated on real data
        robot, fit = ur10_fit
        robot, world = robot.calibrated(fit), fit.registration()
    elif which == "iiwa14":  # 7 joints
        robot, world = stiff.Robot(root / "tests/data/urdf/iiwa14.urdf"), None
    else:  # standard DH with masses, nominal
        robot, world = stiff.Robot("puma560"), None
    text = robot.to_urdf(world)
    q = _random_q(robot, 30, 2)
    expected = robot.tool_pose(q)
    _same_fk(expected, [urdf_fk(text, qi, "base_link", "tcp") for qi in q])
    if world is not None:
        _same_fk([world @ e for e in expected], [urdf_fk(text, qi, "world", "tcp") for qi in q])
    # Joint limits as in the robot: the offsets are in the origins, the joint variable is
    # the controller's.
    lo, hi = robot.limits
    joints = [j for j in ET.fromstring(text).findall("joint") if j.get("type") == "revolute"]
    assert [j.get("name") for j in joints] == robot.joint_names
    np.testing.assert_array_equal([float(j.find("limit").get("lower")) for j in joints], lo)
    np.testing.assert_array_equal([float(j.find("limit").get("upper")) for j in joints], hi)


def test_masses_are_carried_over(root):
    robot = stiff.Robot("puma560")
    root_el = ET.fromstring(robot.to_urdf())
    masses = [float(m.get("value")) for m in root_el.iter("mass")]
    assert sum(masses) == pytest.approx(17.4 + 4.8 + 0.82 + 0.34 + 0.09, rel=1e-12)


def test_cli_writes_the_calibrated_urdf_in_the_tracker_frame(ur5_fit, tmp_path):
    robot, fit = ur5_fit
    fit_path = tmp_path / "fit.json"
    fit.write(fit_path)
    out = tmp_path / "cal.urdf"
    r = subprocess.run([sys.executable, "-m", "stiff.cli", "robot", "show", "--robot", "ur5",
                        "--fit", str(fit_path), "--urdf", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "world" in r.stdout
    q = _random_q(robot, 10, 3)
    placed = stiff.Robot(out, base="world", tip="tcp")
    expected = [fit.registration() @ t for t in robot.calibrated(fit).tool_pose(q)]
    _same_fk(expected, placed.tool_pose(q))
    # --session names a placement the fit does not have: a clear error, nothing written.
    other = tmp_path / "other.urdf"
    r = subprocess.run([sys.executable, "-m", "stiff.cli", "robot", "show", "--robot", "ur5",
                        "--fit", str(fit_path), "--urdf", str(other), "--session", "nope"],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "no session 'nope'" in r.stderr, r.stderr
    assert not other.exists()


def test_a_fit_of_another_robot_is_refused(ur10_fit):
    _, fit = ur10_fit
    with pytest.raises(stiff.InvalidArgumentError, match="robot"):
        stiff.Robot("ur5").calibrated(fit)


def test_unwritable_path_leaves_nothing(ur5_fit, tmp_path):
    robot, fit = ur5_fit
    cal = robot.calibrated(fit)
    ro = tmp_path / "ro"
    ro.mkdir()
    old = ro / "cal.urdf"
    old.write_text("previous")
    old.chmod(0o444)
    with pytest.raises(stiff.StiffError):
        cal.save(old)
    assert old.read_text() == "previous"
    with pytest.raises(stiff.StiffError):
        cal.save(tmp_path / "missing_dir" / "cal.urdf")
    assert not (tmp_path / "missing_dir").exists()
    with pytest.raises(ValueError, match=r"\.urdf"):
        cal.save(tmp_path / "cal.txt")
    with pytest.raises(ValueError, match="4 x 4"):
        cal.to_urdf(np.eye(3))
    assert sorted(os.listdir(ro)) == ["cal.urdf"]  # no temporary file left behind
    # A bad world pose is refused by the writer, not written.
    with pytest.raises(stiff.InvalidArgumentError, match="rigid"):
        cal.to_urdf(2 * np.eye(4))


def test_hostile_names_are_escaped(tmp_path):
    y = tmp_path / "evil.yaml"
    y.write_text('name: "arm </robot><robot name=\\"x\\"> & \'q\'"\n'
                 "convention: modified_dh\n"
                 "joints:\n"
                 '  - {name: "a<b>&c\\"d", alpha: 0, a: 0, d: 0.3}\n'
                 '  - {name: "-->", alpha: 90, a: 0.1, d: 0, limits: [-90, 90]}\n'
                 "units: {length: m, angle: deg}\n")
    robot = stiff.Robot(y)
    text = robot.to_urdf()
    root = ET.fromstring(text)  # well-formed
    assert root.get("name") == robot.name
    assert [j.get("name") for j in root.findall("joint") if j.get("type") == "revolute"] == \
        robot.joint_names
    robot.save(tmp_path / "evil.urdf")
    again = stiff.Robot(tmp_path / "evil.urdf", tip="tcp")
    assert again.name == robot.name and again.joint_names == robot.joint_names


def test_registration_of_a_fit(ur5_fit):
    _, fit = ur5_fit
    w = fit.registration()
    assert w.shape == (4, 4)
    np.testing.assert_allclose(w[:3, :3] @ w[:3, :3].T, np.eye(3), atol=1e-12)
    with pytest.raises(stiff.InvalidArgumentError, match="no session 'x'"):
        fit.registration("x")
