"""The FMU of an absolute calibration (the UR5 tracker data, Jacobi 2025): its tool position is
the calibrated robot's (the corrected chain, not the nominal one), and its q_cmd brings the
calibrated tool to the nominal pose at q; the registration of the fit's session is a parameter
block of the FMU, not part of its outputs (they are in the robot's base frame)."""
import pathlib

import numpy as np
import pytest

pytest.importorskip("fmpy")
from test_fmu import Instance  # noqa: E402

import stiff  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
GEOMETRY = "registration+tool+joint_offset+kinematic"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    robot = stiff.Robot("ur5")
    grid = stiff.Dataset.read(ROOT / "examples/real/ur5/ur5_grid.csv", robot)
    test = stiff.Dataset.read(ROOT / "examples/real/ur5/ur5_random.csv", robot)
    fit = stiff.identify(robot, grid, model=GEOMETRY)
    return robot, fit, test.q[:5]


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_outputs_the_calibrated_tool_and_compensates_it(calibrated, version, tmp_path):
    robot, fit, poses = calibrated
    path = stiff.export_fmu(robot, fit, tmp_path / f"ur5_cal{version}.fmu", version)
    cal = robot.calibrated(fit)
    a = Instance(str(path)).start()
    for q in poses:
        a.set_inputs(q, np.zeros(6))
        tool = a.get(["x_tool", "y_tool", "z_tool"])
        # The calibrated robot's forward kinematics (RobotModel's chain), not the nominal one:
        # they differ by the fitted target offset and geometry (tens of millimetres here).
        assert np.abs(tool - cal.tool_pose(q)[:3, 3]).max() < 1e-12
        assert np.abs(tool - robot.tool_pose(q)[:3, 3]).max() > 1e-3
        qc = a.qcmd()
        reached = cal.tool_pose(qc)
        target = robot.tool_pose(q)
        assert np.abs(reached[:3, 3] - target[:3, 3]).max() < 1e-12
        assert np.abs(reached[:3, :3] - target[:3, :3]).max() < 1e-12
    a.free()
