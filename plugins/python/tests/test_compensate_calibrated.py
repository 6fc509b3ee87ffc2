"""Compensation with a calibration of absolute accuracy (the UR5 tracker data, Jacobi 2025):
the commanded joints bring the CALIBRATED model's tool to the nominal target. Checked through
another path of the library: the fit's own prediction of tracker readings at the command
(`Model.predict_dataset` of absolute rows, mapped back to the base by the fit's registration),
and, for a geometry-only fit, the calibrated robot's plain forward kinematics."""
import numpy as np
import pytest

import stiff
from stiff.compensate import compensate_pose

GEOMETRY = "registration+tool+joint_offset+kinematic"


@pytest.fixture(scope="module")
def ur5(root):
    robot = stiff.Robot("ur5")
    grid = stiff.Dataset.read(root / "examples/real/ur5/ur5_grid.csv", robot)
    test = stiff.Dataset.read(root / "examples/real/ur5/ur5_random.csv", robot)
    return robot, grid, test


def _model_positions(robot, model, fit, q, tmp_path):
    """Where the fit puts the target at joints q, base frame [m]: absolute rows of the fit's
    session predicted in the tracker frame, then mapped back by the registration."""
    p = tmp_path / "rows.csv"
    head = "id,session," + ",".join(f"q{j + 1}_rad" for j in range(robot.dof)) + ",px_m,py_m,pz_m"
    rows = [f"r{i},ur5," + ",".join(repr(float(x)) for x in qi) + ",0,0,0"
            for i, qi in enumerate(q)]
    p.write_text("\n".join([head] + rows) + "\n")
    tracker = model.predict_dataset(stiff.Dataset.read(p, robot))
    w = fit.registration()
    return (tracker - w[:3, 3]) @ w[:3, :3]


@pytest.mark.parametrize("effects", [GEOMETRY, GEOMETRY + "+gravity_lumped"])
def test_command_reaches_the_target_in_the_calibrated_model(ur5, effects, tmp_path):
    robot, grid, test = ur5
    fit = stiff.identify(robot, grid, model=effects)
    model = stiff.Model(robot, fit)
    targets = robot.tool_pose(test.q)
    q_cmd = np.array([compensate_pose(model, q, np.zeros(6)) for q in test.q])
    reached = _model_positions(robot, model, fit, q_cmd, tmp_path)
    # The solver stops at 1e-12 m; what is left is round-off of the chain (~1e-15 m).
    assert np.linalg.norm(reached - targets[:, :3, 3], axis=1).max() < 1e-12
    # The nominal command misses: the target offset on the flange (33.7 mm here, the tool
    # effect) and the geometry besides it (1.5-1.7 mm mean on these poses).
    missed = _model_positions(robot, model, fit, test.q, tmp_path)
    assert np.linalg.norm(missed - targets[:, :3, 3], axis=1).min() > 1e-2
    cal = robot.calibrated(fit)
    same_tool = stiff.Robot("ur5", measured_point=cal.measured_point)
    geometry = np.linalg.norm(missed - same_tool.tool_pose(test.q)[:, :3, 3], axis=1)
    assert geometry.mean() > 1e-3
    if effects == GEOMETRY:
        # Nothing in this fit depends on the pose: the calibrated robot's forward kinematics
        # (RobotModel's chain, not the model's corrected one) is at the target in position
        # and orientation.
        got = cal.tool_pose(q_cmd)
        assert np.abs(got[:, :3, 3] - targets[:, :3, 3]).max() < 1e-12
        assert np.abs(got[:, :3, :3] - targets[:, :3, :3]).max() < 1e-12


def test_process_load_is_compensated_on_top_of_the_geometry(ur5):
    """With joint compliance in the calibration (joint 2's is what these data determine), a
    process force moves the command by minus the deflection it predicts: the calibrated tool
    at the loaded command is where it is at the unloaded one, shifted by -d. The two differ by
    the deflection's change over that shift, second order (|d| / reach ~ 1e-3 of d)."""
    robot, grid, _ = ur5
    fit = stiff.identify(robot, grid, model=GEOMETRY + "+joint")
    model = stiff.Model(robot, fit)
    cal = robot.calibrated(fit)
    q = np.radians([20.0, -80.0, 90.0, -30.0, 95.0, 5.0])
    wrench = [0.0, 0.0, -200.0, 0.0, 0.0, 0.0]
    free = compensate_pose(model, q, np.zeros(6))
    loaded = compensate_pose(model, q, wrench)
    d = np.ravel(model.predict(loaded, wrench))[:3]
    shift = cal.tool_pose(loaded)[:3, 3] - cal.tool_pose(free)[:3, 3]
    assert np.linalg.norm(d) > 1e-4
    assert np.linalg.norm(shift + d) < 1e-2 * np.linalg.norm(d)
