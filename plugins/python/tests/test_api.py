"""The Python API over the C ABI: every test here also exercises the ABI."""
import subprocess

import numpy as np
import pytest

import stiff
from pystiff_support import PAPER_K


def test_c_program_and_python_identify_the_same_to_1e12(build_dir, root, rokae_path, design_a, tmp_path):
    exe = build_dir / "tests" / "c" / "stiff_c_usage_test"
    if not exe.exists():
        pytest.skip(f"{exe} not built")
    out = subprocess.run([str(exe), str(root), str(tmp_path / "fit.json")], check=True,
                         capture_output=True, text=True).stdout
    c_values = np.array([float(line.split()[1]) for line in out.splitlines() if line.startswith("c")])
    robot = stiff.Robot(rokae_path)
    data = stiff.simulate(robot, stiff.Dataset.read(design_a, robot), stiffness=PAPER_K,
                          tracker_sigma_m=10e-6, seed=42)
    fit = stiff.identify(robot, data)
    np.testing.assert_allclose(fit.parameters, c_values, rtol=1e-12, atol=0)


def test_noise_free_round_trip_recovers_stiffness(rokae_path, design_a):
    robot = stiff.Robot(rokae_path)
    data = stiff.simulate(robot, stiff.Dataset.read(design_a, robot), stiffness=PAPER_K, tracker_sigma_m=0.0)
    fit = stiff.identify(robot, data)
    np.testing.assert_allclose(fit.stiffness[:5], PAPER_K[:5], rtol=1e-9)
    assert np.isinf(fit.stiffness[5]) and not fit.identified[5]
    assert fit.joint_status[5] == "not identified, held infinitely stiff (c = 0)"
    assert "joint 6: not identified, held infinitely stiff (c = 0)" in fit.summary()
    assert "joint 6" in fit.warnings[0]


def test_prediction_matches_the_paper_model(rokae_path):
    # d = J C J^T F computed here in numpy from the Jacobian the library exports.
    robot = stiff.Robot(rokae_path)
    fit_data = stiff.simulate(robot, stiff.random_design(robot, 30, seed=3), stiffness=PAPER_K, tracker_sigma_m=0)
    fit = stiff.identify(robot, fit_data)
    model = stiff.Model(robot, fit)
    rng = np.random.default_rng(1)
    lo, hi = robot.limits
    for _ in range(5):
        q = rng.uniform(np.maximum(lo, -3), np.minimum(hi, 3))
        f = rng.uniform(-30, 30, 3)
        jt = robot.jacobian(q)[:3]
        c = np.nan_to_num(1.0 / fit.stiffness)
        expected = jt @ np.diag(c) @ jt.T @ f
        np.testing.assert_allclose(model.predict(q, f)[:3], expected, rtol=1e-10, atol=1e-15)


def test_tool_pose_and_jacobian_take_a_batch(rokae_path):
    # (N, n) in, (N, ...) out, row for row the same as one pose at a time (the batch pose is
    # one C call, the per-pose call another: they must agree to the last bit of the chain).
    robot = stiff.Robot(rokae_path)
    lo, hi = robot.limits
    q = np.random.default_rng(4).uniform(np.maximum(lo, -3), np.minimum(hi, 3), (7, robot.dof))
    poses, jac = robot.tool_pose(q), robot.jacobian(q)
    assert poses.shape == (7, 4, 4) and jac.shape == (7, 6, robot.dof)
    for i in range(7):
        np.testing.assert_allclose(poses[i], robot.tool_pose(q[i]), rtol=0, atol=1e-15)
        np.testing.assert_array_equal(jac[i], robot.jacobian(q[i]))
    assert robot.tool_pose(q[:0]).shape == (0, 4, 4)
    with pytest.raises(stiff.InvalidArgumentError, match="5 values per row"):
        robot.tool_pose(q[:, :5])  # wrong width: named, not read past
    with pytest.raises(stiff.InvalidArgumentError, match="5 values per row"):
        robot.jacobian(q[:, :5])
    assert robot.jacobian(q[:0]).shape == (0, 6, robot.dof)
    with pytest.raises(ValueError):
        robot.tool_pose(q[None])


def test_errors_carry_status_and_location(tmp_path, rokae_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N\na,1,2,3,4,5,6,1,2,zz\n")
    robot = stiff.Robot(rokae_path)
    with pytest.raises(stiff.ParseError) as e:
        stiff.Dataset.read(bad, robot)
    assert e.value.path == str(bad) and e.value.line == 2 and e.value.column == 19
    assert "not a number" in str(e.value)
    with pytest.raises(stiff.StiffIOError):
        stiff.Robot(tmp_path / "missing.yaml")
    with pytest.raises(stiff.InvalidArgumentError, match="unknown effect 'warp'"):
        stiff.identify(robot, stiff.simulate(robot, stiff.random_design(robot, 10), stiffness=PAPER_K), model="joint+warp")


def test_dataset_from_arrays_round_trip(tmp_path):
    q = np.arange(12.0).reshape(2, 6) * 0.1
    f = np.array([[1.0, 2, 3], [4, 5, 6]])
    d = np.array([[1e-4, 2e-4, 3e-4], [4e-4, 5e-4, 6e-4]])
    ds = stiff.Dataset.from_arrays(q, f, displacement=d)
    ds.write(tmp_path / "x.csv")
    back = stiff.Dataset.read(tmp_path / "x.csv")
    np.testing.assert_array_equal(back.q, q)
    np.testing.assert_array_equal(back.displacement, d)
    assert repr(back).startswith("Dataset(2 measurements")


def test_effect_registry_lists_every_effect():
    names = stiff.effects()
    assert "joint" in names
    info = stiff.describe_effect("joint")
    assert info["parameters"][0]["unit"] == "rad/(N*m)"


def test_plots_draw_real_data(rokae_path, design_a, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stiff import plots

    robot = stiff.Robot(rokae_path)
    data = stiff.simulate(robot, stiff.Dataset.read(design_a, robot), stiffness=PAPER_K, seed=4)
    fit = stiff.identify(robot, data)
    ax = plots.residuals(fit, data)
    assert len(ax.patches) == 3 * len(data)
    ax = plots.prediction_error(robot, {"joint": fit}, data)
    assert "RMS" in ax.get_legend().get_texts()[0].get_text()
    plots.stiffness(fit, PAPER_K).figure.savefig(tmp_path / "k.png")
    assert (tmp_path / "k.png").stat().st_size > 1000
    plt.close("all")


def test_dataframes_without_pandas_say_what_to_do(rokae_path, design_a, monkeypatch):
    import sys

    robot = stiff.Robot("rokae")  # built-in robots by name, as on the command line
    assert robot.dof == 6 and robot.path.endswith("rokae.yaml")
    data = stiff.simulate(robot, stiff.Dataset.read(design_a, robot), stiffness=PAPER_K)
    fit = stiff.identify(robot, data)
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if pandas were not installed
    with pytest.raises(ImportError, match="needs pandas.*Fit.parameter_table"):
        fit.to_dataframe()
    with pytest.raises(ImportError, match="needs pandas"):
        data.to_dataframe()


def test_random_design_options_are_the_pools(rokae_path):
    # Every option is checked here against the robot's own forward kinematics and SVD, not
    # against the sampler: q6 held, loads on the 5 N grid, the measured point in the box,
    # no pose with sigma_min of the translational Jacobian below the bound.
    robot = stiff.Robot(rokae_path)
    box = (np.array([0.3, -0.4, -0.8]), np.array([0.9, 0.4, 0.2]))
    q_fixed = [np.nan] * 5 + [0.25]
    d = stiff.random_design(robot, 40, seed=7, q_fixed=q_fixed, load_range_N=(10, 30),
                            load_step_N=5, min_sigma_m=0.08, workspace_box_m=box)
    q, f = d.q, d.force
    assert q.shape == (40, 6) and f.shape == (40, 3)
    lo, hi = robot.limits
    mid, half = (lo + hi) / 2, (hi - lo) / 2 * 0.95
    assert np.all(q[:, :5] >= (mid - half)[:5]) and np.all(q[:, :5] <= (mid + half)[:5])
    np.testing.assert_array_equal(q[:, 5], 0.25)
    mags = np.abs(f)
    assert np.all(np.isin(mags, [10.0, 15.0, 20.0, 25.0, 30.0]))
    assert np.any(f < 0) and np.any(f > 0)
    p = robot.tool_pose(q)[:, :3, 3]
    assert np.all(p >= box[0]) and np.all(p <= box[1])
    s = np.array([np.linalg.svd(j[:3], compute_uv=False)[-1] for j in robot.jacobian(q)])
    assert s.min() >= 0.08
    # Same seed and options, same design; a continuous load range otherwise.
    again = stiff.random_design(robot, 40, seed=7, q_fixed=q_fixed, load_range_N=(10, 30),
                                load_step_N=5, min_sigma_m=0.08, workspace_box_m=box)
    np.testing.assert_array_equal(again.q, q)
    plain = stiff.random_design(robot, 200, seed=7).force
    assert np.all((np.abs(plain) >= 15) & (np.abs(plain) <= 35))
    assert len(np.unique(np.abs(plain))) > 100


def test_random_design_bad_options_name_the_field(rokae_path):
    robot = stiff.Robot(rokae_path)
    with pytest.raises(stiff.InvalidArgumentError, match="workspace box"):
        stiff.random_design(robot, 5, workspace_box_m=([0, 0, 0], [1, -1, 1]))
    with pytest.raises(stiff.InvalidArgumentError, match="q_fixed has 2 values"):
        stiff.random_design(robot, 5, q_fixed=[0, 0])
    with pytest.raises(stiff.InvalidArgumentError, match="load step"):
        stiff.random_design(robot, 5, load_range_N=(16, 19), load_step_N=5)
    with pytest.raises(stiff.InvalidArgumentError, match="range fraction"):
        stiff.random_design(robot, 5, range_fraction=1.5)
