"""A measured validation file is a session of its own: its drift (the warm-up restarts) is
estimated from its readings, cross-fitted, by `stiff predict` as by `stiff diagnose`, so that
identify + predict and the diagnosis report the same validation error (docs/effects.md, drift)."""
import numpy as np
import pytest

import stiff
from stiff.cli import main

PAPER_K = [5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3]


def _truth(path, offset_x, rate_x):
    path.write_text("stiffness_Nm_per_rad: [" + ", ".join(map(str, PAPER_K)) + "]\n"
                    f"effects:\n  drift: {{offset_x: {offset_x}, rate_x: {rate_x}}}\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("sessions")
    noise = ["--tracker-sigma-um", "5"]
    # Another day: the validation session's warm-up has another offset and rate.
    for name, count, seed, truth in (("calib.csv", 60, 1, _truth(d / "tc.yaml", 3e-5, 4e-7)),
                                     ("valid.csv", 40, 2, _truth(d / "tv.yaml", -2e-5, 8e-7))):
        assert main(["simulate", "--robot", "rokae", "--count", str(count), "--seed", str(seed),
                     "--truth", str(truth), *noise, "-o", str(d / name)]) == 0
    assert main(["identify", "--robot", "rokae", "--data", str(d / "calib.csv"),
                 "--model", "joint+drift", "-o", str(d / "fit.json")]) == 0
    return d


def test_predict_and_diagnose_score_a_new_session_alike(files):
    robot = stiff.Robot("rokae")
    valid = stiff.Dataset.read(files / "valid.csv", robot)
    model = stiff.Model(robot, stiff.Fit.read(files / "fit.json"))
    own = model.predict_dataset(valid, cross_fit_sessions=True)
    carried = model.predict_dataset(valid)
    rms = lambda p: float(np.sqrt(np.mean((valid.displacement - p) ** 2)))
    d = stiff.diagnose(robot, stiff.Dataset.read(files / "calib.csv", robot), valid,
                       model="joint+drift", candidates="link")
    # One path: the same fit (to the solver's tolerance) and the same cross-fitted drift.
    assert rms(own) == pytest.approx(d["fit"]["validation_rms_m"], rel=1e-3)
    # The calibration session's drift does not carry over to another day: its offset of 30 um
    # against the validation's -20 um is far beyond the 5 um noise.
    assert rms(carried) > 3 * rms(own)


def test_cli_says_how_the_session_was_predicted(files, capsys):
    args = ["predict", "--robot", "rokae", "--fit", str(files / "fit.json"),
            "--data", str(files / "valid.csv")]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "cross-fitted" in out
    assert main(args + ["--calibration-session"]) == 0
    assert "cross-fitted" not in capsys.readouterr().out


def test_cross_fitting_needs_measured_rows(files, tmp_path):
    robot = stiff.Robot("rokae")
    model = stiff.Model(robot, stiff.Fit.read(files / "fit.json"))
    plan = tmp_path / "plan.csv"
    lines = (files / "valid.csv").read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")][0]
    cols = lines[head].split(",")
    keep = [i for i, c in enumerate(cols) if not c.startswith(("dx", "dy", "dz", "sigma"))]
    plan.write_text("\n".join(lines[:head] + [",".join(r.split(",")[i] for i in keep)
                                              for r in lines[head:] if r]) + "\n")
    data = stiff.Dataset.read(plan, robot)
    with pytest.raises(stiff.StiffError, match="(?i)displacement|measure"):
        model.predict_dataset(data, cross_fit_sessions=True)
