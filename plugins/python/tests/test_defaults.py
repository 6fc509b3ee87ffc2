"""Every default of the Python package and of the command line is the library's: an argument
left unset gives the result of NULL options in the C ABI, the help texts show the values the
stiff_*_options_init calls write, and the library's checks reach every surface unchanged."""
import ctypes as C
import inspect
import json
import subprocess
import sys

import numpy as np
import pytest

import stiff
from stiff import _capi
from stiff.compensate import path_defaults, read_path

K = [5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3]


def cli(*args, check=True):
    return subprocess.run([sys.executable, "-m", "stiff.cli", *map(str, args)],
                          capture_output=True, text=True, check=check)


def help_of(*command) -> str:
    return " ".join(cli(*command, "--help").stdout.split())


@pytest.fixture(scope="module")
def robot(rokae_path):
    return stiff.Robot(rokae_path)


@pytest.fixture(scope="module")
def design(robot):
    return stiff.random_design(robot, 40, 3)


def c_simulate(robot, design, noise_ptr):
    h = C.c_void_p()
    k = np.array(K)
    _capi.check(_capi.lib.stiff_simulate(C.byref(h), robot, design, None, _capi.ptr(k), 6,
                                         noise_ptr))
    return stiff.Dataset(h)


@pytest.fixture(scope="module")
def measured(robot, design):
    return c_simulate(robot, design, None)


def test_option_arguments_default_to_none_so_the_library_decides():
    # An argument with a library default is None in the signature: nothing is restated here.
    for fn, names in ((stiff.identify, ("model", "loss", "loss_scale_m", "method",
                                        "max_iterations", "max_relative_se",
                                        "select_terms")),
                      (stiff.simulate, ("tracker_sigma_m", "tracker_ppm", "force_relative",
                                        "force_absolute_N", "joint_sigma_rad", "outlier_rate",
                                        "outlier_size_m", "seed", "tracker_position_m")),
                      (stiff.diagnose, ("model", "candidates", "alpha", "auto_steps",
                                        "command_prefix", "auto_loop")),
                      (stiff.export_fmu, ("fmi_version", "model_identifier", "array_inputs")),
                      (read_path, ("frame", "tool_rpy", "segment_m")),
                      (stiff.plan, ("count", "criterion", "seed", "annealing_iterations"))):
        params = inspect.signature(fn).parameters
        for n in names:
            assert params[n].default is None, f"{fn.__name__}({n}=...)"


def test_defaults_are_what_the_init_calls_write():
    o = _capi.defaults(_capi.IdentifyOptions)
    assert stiff.identify_defaults() == {
        "model": o.model.decode(), "loss": o.loss.decode(), "loss_scale_m": o.loss_scale_m,
        "method": "auto", "max_iterations": o.max_iterations,
        "max_relative_se": o.max_relative_se,
        # 0 in C: estimated from the residuals (None in Python)
        "orientation_length_m": o.orientation_length_m or None,
        "select_terms": o.select_terms > 0}
    n = _capi.defaults(_capi.NoiseOptions)
    d = stiff.noise_defaults()
    assert d["tracker_sigma_m"] == n.tracker_sigma_m > 0 and d["seed"] == n.seed
    assert d["tracker_position_m"] == list(n.tracker_position_m)
    assert stiff.diagnose_defaults()["alpha"] == _capi.defaults(_capi.DiagnoseOptions).alpha
    assert stiff.fmu_defaults()["fmi_version"] == _capi.defaults(_capi.FmuOptions).fmi_version
    # The init calls refuse a struct size that is no version of the struct.
    for struct in (_capi.IdentifyOptions, _capi.NoiseOptions, _capi.RobotOptions,
                   _capi.DiagnoseOptions, _capi.FmuOptions, _capi.PathOptions):
        o = struct()
        status = getattr(_capi.lib, struct._init_)(C.byref(o), 3)
        assert status == stiff.InvalidArgumentError.status
        assert "struct_size 3" in _capi.last_error()


def test_identify_with_unset_arguments_is_identify_with_null_options(robot, measured):
    h = C.c_void_p()
    _capi.check(_capi.lib.stiff_identify(C.byref(h), robot, measured, None))
    null = stiff.Fit(h)
    assert stiff.identify(robot, measured).json == null.json
    assert null.model == [stiff.identify_defaults()["model"]]


def test_cli_identify_leaves_unset_options_to_the_library(robot, measured, rokae_path, tmp_path):
    measured.write(tmp_path / "m.csv")
    cli("identify", "--robot", rokae_path, "--data", tmp_path / "m.csv", "-o", tmp_path / "f.json")
    h = C.c_void_p()
    _capi.check(_capi.lib.stiff_identify(C.byref(h), robot,
                                         stiff.Dataset.read(tmp_path / "m.csv", robot), None))
    np.testing.assert_array_equal(stiff.Fit.read(tmp_path / "f.json").parameters,
                                  stiff.Fit(h).parameters)
    d = stiff.identify_defaults()
    text = help_of("identify")
    assert f"default {d['loss']})" in text and f"default {d['max_relative_se']:g})" in text
    assert f"default {d['method']}:" in text


def test_simulate_with_unset_noise_is_the_null_noise(robot, design, measured, rokae_path,
                                                     tmp_path):
    py = stiff.simulate(robot, design, stiffness=K)
    np.testing.assert_array_equal(py.displacement, measured.displacement)
    # The default noise is noise: an explicit zero is exact data.
    exact = stiff.simulate(robot, design, stiffness=K, tracker_sigma_m=0.0)
    assert not np.array_equal(exact.displacement, measured.displacement)
    design.write(tmp_path / "design.csv")
    cli("simulate", "--robot", rokae_path, "--plan", tmp_path / "design.csv",
        "--stiffness", ",".join(map(str, K)), "-o", tmp_path / "sim.csv")
    from_cli = stiff.Dataset.read(tmp_path / "sim.csv", robot)
    np.testing.assert_allclose(from_cli.displacement, measured.displacement, rtol=1e-12, atol=0)
    d = stiff.noise_defaults()
    text = help_of("simulate")
    assert f"default {d['tracker_sigma_m'] * 1e6:g})" in text and f"default {d['seed']};" in text


def test_library_checks_reach_python_and_the_cli_unchanged(robot, measured, design, rokae_path,
                                                          tmp_path):
    # identify: the core's message, whichever method solves.
    message = "identify: loss_scale_m must be finite and >= 0 [m]"
    for method in ("linear", "ceres"):
        with pytest.raises(stiff.InvalidArgumentError, match=message.replace("[", r"\[")
                           .replace("]", r"\]")):
            stiff.identify(robot, measured, method=method, loss_scale_m=-1.0)
    measured.write(tmp_path / "m.csv")
    r = cli("identify", "--robot", rokae_path, "--data", tmp_path / "m.csv", "--loss-scale-um",
            "-1", check=False)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr
    # simulate: the core names the noise field.
    with pytest.raises(stiff.InvalidArgumentError, match="noise outlier_rate must be <= 0.5"):
        stiff.simulate(robot, design, stiffness=K, outlier_rate=0.9)
    # diagnose: the core's alpha check, also from the command line.
    with pytest.raises(stiff.InvalidArgumentError, match=r"diagnose: alpha must be in \(0, 1\)"):
        stiff.diagnose(robot, measured, alpha=1.5)
    r = cli("diagnose", "--robot", rokae_path, "--data", tmp_path / "m.csv", "--alpha", "1.5",
            check=False)
    assert r.returncode == 2 and "diagnose: alpha must be in (0, 1)" in r.stderr
    # an alpha of 0 cannot be carried by the C field (0 = default): refused with the same words
    with pytest.raises(stiff.InvalidArgumentError, match=r"diagnose: alpha must be in \(0, 1\)"):
        stiff.diagnose(robot, measured, alpha=0)


def test_diagnose_with_unset_arguments_is_diagnose_with_null_options(robot, measured):
    h = C.c_void_p()
    _capi.check(_capi.lib.stiff_diagnose(C.byref(h), robot, measured, None, None))
    try:
        null = json.loads(_capi.get_string(_capi.lib.stiff_diagnosis_json, h))
    finally:
        _capi.lib.stiff_diagnosis_destroy(h)
    assert stiff.diagnose(robot, measured).json == null
    assert null["model"] == stiff.diagnose_defaults()["model"]


def test_read_path_with_unset_arguments_is_the_null_options(root):
    for name in ("pocket.nc", "rokae_contour.csv"):
        path = root / "examples" / "paths" / name
        rows = C.c_size_t(0)
        _capi.lib.stiff_path_read(None, None, None, 0, C.byref(rows), None, bytes(path), None)
        poses = np.empty((rows.value, 16))
        _capi.check(_capi.lib.stiff_path_read(_capi.ptr(poses), None, None, rows.value,
                                              C.byref(rows), None, bytes(path), None))
        np.testing.assert_array_equal(read_path(path).poses.reshape(-1, 16), poses)
    # the default tool orientation (pointing down) given explicitly changes nothing
    pocket = root / "examples" / "paths" / "pocket.nc"
    np.testing.assert_allclose(read_path(pocket, tool_rpy=path_defaults()["tool_rpy"]).poses,
                               read_path(pocket).poses, atol=1e-12, rtol=0)
    assert path_defaults()["segment_m"] == _capi.defaults(_capi.PathOptions).segment_m


def test_fmu_help_shows_the_library_defaults():
    d = stiff.fmu_defaults()
    text = help_of("fmu", "export")
    assert f"FMI version (default {d['fmi_version']})" in text
    assert f"model identifier (default {d['model_identifier']})" in text


def test_select_terms_reaches_the_library(robot, measured, rokae_path, tmp_path):
    # The data have no nonlinear reducer: by default nonlinear_joint's optional terms are kept
    # only when they lower the BIC (each null term with the chance of a chi2(1) above ln(3N),
    # a few %), so some are left out; select_terms=False (CLI --all-terms) fits them all.
    model = "joint+nonlinear_joint"
    left_out = lambda fit: [w for w in fit.warnings if "is left out" in w]
    default = stiff.identify(robot, measured, model=model)
    assert left_out(default)
    assert stiff.identify(robot, measured, model=model, select_terms=True).json == default.json
    assert not left_out(stiff.identify(robot, measured, model=model, select_terms=False))
    with pytest.raises(TypeError):
        stiff.identify(robot, measured, model=model, select_terms=1)
    measured.write(tmp_path / "m.csv")
    cli("identify", "--robot", rokae_path, "--data", tmp_path / "m.csv", "--model", model,
        "--all-terms", "-o", tmp_path / "all.json")
    assert "is left out" not in (tmp_path / "all.json").read_text()
    cli("identify", "--robot", rokae_path, "--data", tmp_path / "m.csv", "--model", model,
        "-o", tmp_path / "sel.json")
    assert "is left out" in (tmp_path / "sel.json").read_text()
