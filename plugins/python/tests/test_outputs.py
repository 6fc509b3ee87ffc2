"""Outputs never destroy what is at their path: devices and pipes are written through, links
followed, read-only files and inputs refused, and a command's outputs appear only when the whole
command succeeded (docs/reliability.md, "Round two")."""
from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import stiff
from stiff import _outputs

K = "50914,16382,31311,7791,5614,4000"


def cli(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "stiff.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    d = tmp_path_factory.mktemp("good")
    data, fit = d / "data.csv", d / "fit.json"
    assert cli("simulate", "--robot", "rokae", "--count", "12", "--seed", "3", "--stiffness", K,
               "-o", data).returncode == 0
    assert cli("identify", "--robot", "rokae", "--data", data, "-o", fit).returncode == 0
    return {"data": data, "fit": fit}


def test_dev_null_is_written_through_not_replaced(good):
    r = cli("identify", "--robot", "rokae", "--data", good["data"], "-o", "/dev/null")
    assert r.returncode == 0, r.stderr
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    r = cli("identify", "--robot", "rokae", "--data", good["data"], "-o", "/dev/full")
    assert r.returncode == 2 and "/dev/full: write failed (No space left on device)" in r.stderr
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_dash_is_standard_output(good):
    r = cli("simulate", "--robot", "rokae", "--count", "3", "--stiffness", K, "-o", "-")
    assert r.returncode == 0, r.stderr
    assert "dx_m" in r.stdout and not Path("-").exists()


def test_named_pipe_is_written_through(good, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = subprocess.Popen(["cat", str(fifo)], stdout=subprocess.PIPE)
    time.sleep(0.2)
    r = cli("identify", "--robot", "rokae", "--data", good["data"], "-o", fifo)
    out = reader.communicate(timeout=60)[0]
    assert r.returncode == 0, r.stderr
    assert b'"stiff-fit"' in out
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_symlink_is_followed(good, tmp_path):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target.name)
    r = cli("identify", "--robot", "rokae", "--data", good["data"], "-o", link)
    assert r.returncode == 0, r.stderr
    assert link.is_symlink()
    assert '"stiff-fit"' in target.read_text()


def test_read_only_output_is_refused(good, tmp_path):
    ro = tmp_path / "ro.json"
    ro.write_text("keep")
    ro.chmod(0o444)
    r = cli("identify", "--robot", "rokae", "--data", good["data"], "-o", ro)
    assert r.returncode == 2 and "ro.json: is read-only" in r.stderr, r.stderr
    assert ro.read_text() == "keep"


@pytest.mark.parametrize("how", ["same-name", "other-name", "hard-link", "symlink"])
def test_output_that_is_an_input_is_refused(good, tmp_path, how):
    data = tmp_path / "d.csv"
    data.write_bytes(good["data"].read_bytes())
    out = {"same-name": data, "other-name": f"{tmp_path}/./d.csv",
           "hard-link": tmp_path / "hard.csv", "symlink": tmp_path / "sym.csv"}[how]
    if how == "hard-link":
        os.link(data, out)
    if how == "symlink":
        out.symlink_to(data.name)
    before = data.read_bytes()
    for args in (["identify", "--robot", "rokae", "--data", data, "-o", out],
                 ["predict", "--robot", "rokae", "--fit", good["fit"], "--data", data, "-o", out]):
        r = cli(*args)
        assert r.returncode == 2, r.stderr
        assert "is an input of this command" in r.stderr, r.stderr
        assert data.read_bytes() == before


def test_failing_command_commits_no_output(good, tmp_path, root):
    keep = tmp_path / "keep.csv"
    keep.write_text("keep")
    r = cli("compensate", "--robot", "rokae", "--fit", good["fit"], "--path",
            root / "examples/paths/rokae_contour.csv", "--wrench", "0,0,-50",
            "--report", tmp_path / "nodir" / "x.png", "-o", keep)
    assert r.returncode == 2, r.stderr
    assert "nodir" in r.stderr and ".tmp" not in r.stderr
    assert keep.read_text() == "keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.csv"]


def test_errors_never_name_the_staged_file(good, tmp_path):
    r = cli("identify", "--robot", "rokae", "--data", good["data"], "-o",
            tmp_path / ("n" * 300 + ".json"))
    assert r.returncode == 2
    assert "too long" in r.stderr and "Traceback" not in r.stderr
    assert "stiff-" not in r.stderr.split("error:")[1].split(":")[0]


def test_library_writers_outside_a_command_are_direct_and_atomic(good, tmp_path):
    fit = stiff.Fit.read(good["fit"])
    link = tmp_path / "l.json"
    link.symlink_to("t.json")
    fit.write(link)
    assert link.is_symlink() and (tmp_path / "t.json").exists()
    _outputs.write_bytes(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"


def test_transaction_discards_on_error(tmp_path):
    with pytest.raises(RuntimeError):
        with _outputs.transaction():
            _outputs.write_text(tmp_path / "a.txt", "a")
            raise RuntimeError("boom")
    assert not (tmp_path / "a.txt").exists()
    with _outputs.transaction():
        _outputs.write_text(tmp_path / "a.txt", "a")
        assert not (tmp_path / "a.txt").exists()
    assert (tmp_path / "a.txt").read_text() == "a"


# ------------------------------------------------------------------ counts, shapes, strings
@pytest.mark.parametrize("args", [["--iterations=-1"], ["--iterations", "0"], ["--pool-poses", "0"],
                                  ["--count=-3"], ["--pool-loads", "0"]])
def test_counts_must_be_positive(args, tmp_path):
    r = cli("plan", "--robot", "rokae", *args, "-o", tmp_path / "p.csv", timeout=60)
    assert r.returncode == 2, r.stderr
    assert "must be an integer >= 1" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_count_written_as_the_help_writes_it(tmp_path):
    r = cli("plan", "--robot", "rokae", "--iterations", "2e3", "--pool-poses", "60", "-o",
            tmp_path / "p.csv")
    assert r.returncode == 0, r.stderr


def test_model_predict_checks_every_shape(rokae_path, good):
    m = stiff.Model(stiff.Robot(rokae_path), stiff.Fit.read(good["fit"]))
    q = np.full((4, 6), 0.3)
    with pytest.raises(ValueError, match="4 rows and wrench 3"):
        m.predict(q, np.ones((3, 6)))
    for cols in (5, 7):
        with pytest.raises(ValueError, match=f"wrench has {cols} columns"):
            m.predict(q, np.ones((4, cols)))
    with pytest.raises(ValueError, match="q has 7 columns"):
        m.predict(np.zeros((2, 7)), np.ones(6))
    # One wrench for all rows, 3-column forces: still accepted.
    assert m.predict(q, [10, 0, 0]).shape == (4, 6)


def test_tool_poses_checks_the_width(rokae_path):
    from stiff import compensate as cp

    with pytest.raises(stiff.errors.InvalidArgumentError, match="5 values per row"):
        cp.tool_poses(stiff.Robot(rokae_path), np.zeros((2, 5)))


def test_nul_bytes_are_refused_not_truncated(rokae_path, good):
    r, d = stiff.Robot(rokae_path), stiff.Dataset.read(good["data"])
    with pytest.raises(stiff.errors.InvalidArgumentError, match="NUL"):
        stiff.identify(r, d, model="joint\x00+link")
    with pytest.raises(TypeError, match="model must be a string"):
        stiff.identify(r, d, model=3)  # None is the library's default model


# ------------------------------------------------------------------ study files
def test_study_load_reads_data_not_pickles(tmp_path):
    import pickle

    evil = tmp_path / "evil.pkl"
    marker = tmp_path / "ran"
    evil.write_bytes(pickle.dumps(_Evil(str(marker))))
    r = cli("study", "paper", "--load", evil, "-o", tmp_path / "r.md")
    assert r.returncode == 2 and "not a study file" in r.stderr, r.stderr
    assert not marker.exists()


class _Evil:
    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (os.system, (f"touch {self.path}",))


def test_study_output_must_be_markdown(tmp_path):
    r = cli("study", "paper", "--trials", "2", "-o", tmp_path / "report")
    assert r.returncode == 2 and "ending in .md" in r.stderr


def test_sigterm_stops_study_workers_quietly(tmp_path):
    p = subprocess.Popen([sys.executable, "-m", "stiff.cli", "study", "paper", "--trials", "50",
                          "--jobs", "2", "-o", str(tmp_path / "s.md"), "--save",
                          str(tmp_path / "s.json")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # Once both workers run (their trials take seconds each), terminate the command.
    deadline = time.time() + 120
    while time.time() < deadline:
        try:
            kids = Path(f"/proc/{p.pid}/task/{p.pid}/children").read_text().split()
        except OSError:
            kids = []
        if len(kids) >= 2:
            break
        time.sleep(0.1)
    time.sleep(1.0)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 143, err
    assert err.strip().splitlines() == ["stiff study: terminated"], err
    assert list(tmp_path.iterdir()) == []


def test_formats_md_truth_example_is_read(root, rokae_path, tmp_path):
    text = (root / "docs" / "formats.md").read_text()
    block = text.split("## Truth files")[1].split("```yaml\n")[1].split("```")[0]
    (tmp_path / "truth.yaml").write_text(block)
    d = stiff.simulate(stiff.Robot(rokae_path), stiff.random_design(stiff.Robot(rokae_path), 3),
                       truth=tmp_path / "truth.yaml")
    assert np.isfinite(d.displacement).all()


def test_study_save_and_load_round_trip(tmp_path):
    a, b, saved = tmp_path / "a.md", tmp_path / "b.md", tmp_path / "s.json"
    r = cli("study", "paper", "--trials", "2", "--jobs", "1", "--iterations", "500",
            "--pool-poses", "40", "--pool-loads", "10", "-o", a, "--save", saved)
    assert r.returncode == 0, r.stderr
    assert saved.read_text().startswith('{"format": "stiff-study"')
    r = cli("study", "paper", "--load", saved, "-o", b)
    assert r.returncode == 0, r.stderr
    # The same report, up to the folder of its plots (named after the report).
    assert a.read_text() == b.read_text().replace("](b/", "](a/")


def test_identify_warns_about_implausible_data(good, tmp_path):
    """Displacements in mm declared _m: stiffness ~50 N*m/rad, far below any robot's; an axis
    that is zero in every row is a missing tracker axis, not a perfect fit."""
    text = good["data"].read_text().splitlines()
    head = [i for i, l in enumerate(text) if not l.startswith("#")][0]
    cols = text[head].split(",")
    rows = [l.split(",") for l in text[head + 1:]]
    dz = cols.index("dz_m")
    for r in rows:
        for c in (cols.index("dx_m"), cols.index("dy_m")):
            r[c] = repr(float(r[c]) * 1e3)
        r[dz] = "0"
    bad = tmp_path / "mm_as_m.csv"
    bad.write_text("\n".join(text[:head + 1] + [",".join(r) for r in rows]) + "\n")
    r = cli("identify", "--robot", "rokae", "--data", bad)
    # Nothing is determined (the compliances that would fit are thousands of typical
    # magnitudes uncertain): the fit fails, says so and what is wrong with the data, instead of
    # printing a stiffness.
    assert r.returncode == 2, r.stdout
    assert "no joint compliance is determined by this data" in r.stderr, r.stderr
    assert "wrong unit" in r.stderr and "dz is zero in every measurement" in r.stderr, r.stderr
    assert not r.stdout


def test_identify_warns_about_a_stiffness_no_robot_has(good, tmp_path):
    """Every displacement in mm declared _m: well determined, 1000 times too compliant."""
    text = good["data"].read_text().splitlines()
    head = [i for i, l in enumerate(text) if not l.startswith("#")][0]
    cols = text[head].split(",")
    rows = [l.split(",") for l in text[head + 1:]]
    for r in rows:
        for c in ("dx_m", "dy_m", "dz_m"):
            r[cols.index(c)] = repr(float(r[cols.index(c)]) * 1e3)
    bad = tmp_path / "mm_as_m.csv"
    bad.write_text("\n".join(text[:head + 1] + [",".join(r) for r in rows]) + "\n")
    r = cli("identify", "--robot", "rokae", "--data", bad)
    assert r.returncode == 0, r.stderr
    assert "is outside 1e2..1e8 N*m/rad" in r.stdout, r.stdout
