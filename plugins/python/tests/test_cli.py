"""The `stiff` command line, run as a user runs it."""
import json
import subprocess
import sys

import pytest

STIFF = [sys.executable, "-m", "stiff.cli"]


def run(*args, check=True):
    p = subprocess.run(STIFF + [str(a) for a in args], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"stiff {' '.join(map(str, args))} failed ({p.returncode}):\n{p.stderr}")
    return p


def test_version():
    assert run("--version").stdout.startswith("stiff 0.1.0")


def test_simulate_identify_predict(tmp_path, rokae_path, design_a):
    data = tmp_path / "data.csv"
    run("simulate", "--robot", rokae_path, "--plan", design_a,
        "--stiffness", "50914,16382,31311,7791.1,5613.6,4000", "-o", data)
    out = run("identify", "--robot", "rokae", "--data", data, "-o", tmp_path / "fit.json").stdout
    assert "not identifiable from this data: joint 6" in out
    fit = json.loads((tmp_path / "fit.json").read_text())
    assert fit["format"] == "stiff-fit" and fit["joints"][5]["identified"] is False
    pred = run("predict", "--robot", "rokae", "--fit", tmp_path / "fit.json", "--data", data,
               "-o", tmp_path / "pred.csv").stdout
    assert "RMS" in pred
    lines = (tmp_path / "pred.csv").read_text().splitlines()
    assert any(line.startswith("a01,") for line in lines)  # ids kept


@pytest.mark.parametrize("args, message", [
    (["identify", "--robot", "nosuchrobot", "--data", "x.csv"], "no robot file 'nosuchrobot'"),
    (["identify", "--robot", "rokae", "--data", "/nonexistent.csv"], "/nonexistent.csv"),
    (["simulate", "--robot", "rokae", "-o", "x.csv"], "give the truth"),
])
def test_user_errors_are_one_line_and_exit_2(args, message, tmp_path):
    p = subprocess.run(STIFF + args, capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 2
    assert message in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "Traceback" not in p.stderr


def test_a_compliance_below_zero_is_held_at_its_bound_and_the_fit_predicts(tmp_path):
    # Joint 4 nearly rigid (1e9 N*m/rad): with 10 poses and the simulator's noise, least squares
    # puts its compliance below 0 in about half the seeds. The fit holds it at 0, says so, and
    # predicts (a negative compliance was written before, and predict refused the fit).
    shown = 0
    for seed in range(1, 7):
        data, fit = tmp_path / f"d{seed}.csv", tmp_path / f"f{seed}.json"
        run("simulate", "--robot", "rokae", "--count", "10", "--seed", seed,
            "--stiffness", "50914,16382,31311,1e9,5614,4000", "-o", data)
        out = run("identify", "--robot", "rokae", "--data", data, "-o", fit).stdout
        joint = [q for q in json.loads(fit.read_text())["parameters"] if q["effect"] == "joint"]
        c = [q["value"] for q in joint]
        assert len(c) == 6 and min(c) >= 0, c
        held = [q.get("held") for q in joint]
        run("predict", "--robot", "rokae", "--fit", fit, "--data", data, "-o", tmp_path / "p.csv")
        # The table shows what the fit file says (`held`), for joint 4 alone.
        assert ("rigid (c < 0 held at 0)" in out) == (held[3] == "bound"), (held, out)
        assert all(h != "bound" for j, h in enumerate(held) if j != 3), held
        if "rigid (c < 0 held at 0)" in out:
            shown += 1
            assert "held at the bound c = 0 (least squares put the compliance below 0): joint 4" \
                in out, out
    assert shown >= 2


def test_demo_runs(tmp_path):
    out = run("demo", "--out", tmp_path / "demo").stdout
    assert "verdict:" in out and "compensated with" in out
    for name in ("report.html", "fit_joint.json", "fit_full.json", "arm.fmu", "diagnosis.json"):
        assert (tmp_path / "demo" / name).exists(), name
    # The loop is walked: the hidden SMR offset is named and the validation error falls to
    # about the noise floor (after more measurements: ten planned for the joint model leave the
    # offset's parameters loose at the validation poses, leverage 0.5-0.9, where a right model
    # predicts 1.2-1.4 times the floor), sigma sqrt(1 + p/n) for a right model on the repeat
    # (12 parameters on 60 equations: 1.095),
    # with room for 20 validation poses' own scatter (chi2 of 60 dof: +20 % at 1 %).
    rows = {}
    for line in out.split("== 5.")[1].split("== 6.")[0].splitlines():
        cells = line.split()
        if cells and cells[0].startswith("joint") and len(cells) >= 9:
            rows[cells[0]] = [float(cells[k]) for k in (1, 3, 5, 7)]  # fit, valid, max, floor
    assert set(rows) == {"joint", "joint+point_offset"}, out
    joint, offset = rows["joint"], rows["joint+point_offset"]
    assert offset[1] < 0.7 * joint[1], rows
    assert offset[1] < 1.09 * 1.2 * offset[3], rows


def test_simulated_file_keeps_the_truth_out_unless_asked(tmp_path):
    blind, told = tmp_path / "blind.csv", tmp_path / "told.csv"
    run("simulate", "--robot", "rokae", "--truth", "rokae_backlash", "--count", "5", "-o", blind)
    text = blind.read_text()
    assert "backlash" not in text and "truth" not in text
    run("simulate", "--robot", "rokae", "--truth", "rokae_backlash", "--count", "5",
        "--record-truth", "-o", told)
    assert "# truth_model: joint+backlash" in told.read_text()
    # The same measurements either way; the recorded file still reads.
    import stiff
    a, b = stiff.Dataset.read(blind), stiff.Dataset.read(told)
    assert (a.displacement == b.displacement).all()


def test_examples_lists_and_copies_builtin_files(tmp_path):
    out = run("examples", "--copy", tmp_path / "ex").stdout
    assert "rokae_backlash" in out and "pocket" in out
    assert (tmp_path / "ex" / "paths" / "pocket.nc").is_file()
    assert (tmp_path / "ex" / "robots" / "rokae.yaml").is_file()


def test_effects_of_a_robot_without_masses_lists_every_effect():
    """The ABB IRB 120's file has no link masses: the effects that need them are listed as not
    available (and why), the others with their parameters; asked for by name, one is an error."""
    out = run("effects", "--robot", "abb_irb120").stdout
    assert out.count("not available for this robot") == 2
    assert "coupling" in out and "needs link masses" in out
    infos = json.loads(run("effects", "--robot", "abb_irb120", "--json").stdout)
    off = {i["name"] for i in infos if "unavailable" in i}
    assert off == {"nonlinear_joint", "backlash"}
    assert len(infos) == len(json.loads(run("effects", "--json").stdout))
    p = run("effects", "backlash", "--robot", "abb_irb120", check=False)
    assert p.returncode == 2 and "needs link masses" in p.stderr


def test_fmu_export_array_inputs(tmp_path):
    """`--array-inputs` (FMI 3) gives an FMU whose inputs are q[n] and wrench[6] only; with
    FMI 2 it is a one-line error and nothing is written."""
    import zipfile

    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({
        "format": "stiff-fit", "version": 1, "robot": {"name": "rokae"}, "model": ["joint"],
        "parameters": [{"effect": "joint", "name": f"c{j}", "value": 1e-4} for j in range(1, 7)]}))
    out = tmp_path / "a.fmu"
    said = run("fmu", "export", "--robot", "rokae", "--fit", fit, "--fmi", "3", "--array-inputs",
               "-o", out).stdout
    assert "array inputs" in said
    with zipfile.ZipFile(out) as z:
        xml = z.read("modelDescription.xml").decode()
    inputs = [line for line in xml.splitlines() if 'causality="input"' in line]
    assert [i.split('name="')[1].split('"')[0] for i in inputs] == ["q", "wrench"]
    bad = run("fmu", "export", "--robot", "rokae", "--fit", fit, "--array-inputs",
              "-o", tmp_path / "b.fmu", check=False)
    assert bad.returncode == 2 and "array inputs need FMI 3" in bad.stderr
    assert not (tmp_path / "b.fmu").exists()
