"""bench/diagnosis_score.py, the scoring harness of the diagnosis: its rules, and a run on a
small scenario directory of the same layout as the independent development suite (folders with
calib.csv, valid.csv and truth.json; index.json), made here by the virtual robot."""
import json
import subprocess
import sys

import numpy as np
import pytest

from pystiff_support import PAPER_K, bench_module
from stiff.cli import main

TRACKER_SIGMA_UM = 10.0


@pytest.fixture(scope="module")
def score(root):
    return bench_module(root, "diagnosis_score")


def test_classify_follows_the_documented_rules(score):
    def run(expected, verdict, final="joint", group=(), suggested=None, valid_m=None):
        truth = {"expected": expected, "true_class_refit_valid_um": {"axis_um": 20.0}}
        d = {"verdict": verdict, "final_model": final, "ambiguous_group": list(group),
             "suggested_model": suggested,
             "steps": [{"validation_rms_m": valid_m}] if valid_m else []}
        return score.classify(truth, d)

    one = {"verdict": "missing_effect", "effects": ["point_offset"]}
    assert run(one, "missing_effect", suggested="joint+point_offset")[0] == "right"
    assert run(one, "missing_effect", suggested="joint+link")[0] == "wrong"
    assert run(one, "ambiguous", group=["point_offset", "tool_compliance"])[0] == "right"
    assert run(one, "ambiguous", group=["link"])[0] == "ambiguous"
    assert run(one, "unexplained")[0] == "miss"
    outside = {"verdict": "unexplained"}
    assert run(outside, "unexplained")[0] == "right"
    assert run(outside, "ambiguous", group=["link"])[0] == "right"
    assert run(outside, "missing_effect", suggested="joint+link")[0] == "wrong"
    control = {"verdict": "adequate"}
    assert run(control, "adequate")[0] == "right"
    assert run(control, "missing_effect", suggested="joint+drift")[0] == "wrong"
    both = {"verdict": "missing_effect", "effects": ["point_offset", "backlash"]}
    assert run(both, "missing_effect", "joint+point_offset+backlash")[0] == "right"
    assert run(both, "ambiguous", "joint+point_offset+backlash", ["point_offset"])[0] == "partial"
    assert run(both, "missing_effect", "joint+point_offset")[0] == "partial"
    # The ratio: the final step's validation RMS over what a right model reaches.
    assert run(one, "missing_effect", suggested="joint+point_offset",
               valid_m=25e-6)[4] == pytest.approx(1.25)


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    """Two scenarios of 60 calibration and 40 validation poses with the noise stated: an SMR
    and load point 40 mm off the flange axis, and a control without a hidden effect."""
    d = tmp_path_factory.mktemp("suite")
    k = "stiffness_Nm_per_rad: [" + ", ".join(map(str, PAPER_K)) + "]\n"
    cases = {
        "g_00": ("g", k + "effects:\n  point_offset: {meas_x: 0.04, load_x: 0.04}\n",
                 {"verdict": "missing_effect", "effects": ["point_offset"]}),
        "none_00": ("none", k, {"verdict": "adequate"}),
    }
    index = []
    for name, (kind, truth_yaml, expected) in cases.items():
        folder = d / "base" / name
        folder.mkdir(parents=True)
        (folder / "truth.yaml").write_text(truth_yaml)
        for csv, count, seed in (("calib.csv", 60, 11), ("valid.csv", 40, 12)):
            assert main(["simulate", "--robot", "rokae", "--count", str(count), "--seed",
                         str(seed), "--truth", str(folder / "truth.yaml"), "--tracker-sigma-um",
                         str(TRACKER_SIGMA_UM), "-o", str(folder / csv)]) == 0
        # What a right model reaches on new poses is the tracker noise (per axis).
        (folder / "truth.json").write_text(json.dumps({
            "type": kind, "expected": expected,
            "true_class_refit_valid_um": {"axis_um": TRACKER_SIGMA_UM}}))
        index.append({"path": f"base/{name}", "type": kind})
    (d / "index.json").write_text(json.dumps(index))
    return d


def test_harness_scores_a_scenario_directory(root, suite, tmp_path):
    out = tmp_path / "scores.json"
    p = subprocess.run([sys.executable, str(root / "bench" / "diagnosis_score.py"), "--data",
                        str(suite), "--sets", "base", "--seeds", "0", "--noise", "both",
                        "--jobs", "1", "--json", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    rows = {(r["path"], r["noise"]): r for r in json.loads(out.read_text())}
    # Each file states its noise, so each scenario runs with and without the statement.
    assert set(rows) == {("base/g_00", "given"), ("base/g_00", "unknown"),
                         ("base/none_00", "given"), ("base/none_00", "unknown")}
    for key, r in rows.items():
        assert r["outcome"] == "right", (key, r)
    for noise in ("given", "unknown"):
        # The offset found, the model with it predicts new poses within the 1.25 times
        # what a right model reaches (the tracker noise plus its parameters' prediction error).
        assert rows[("base/g_00", noise)]["final"] == ["point_offset"]
        assert rows[("base/g_00", noise)]["ratio"] < 1.25
    assert "base    g" in p.stdout and "runs in" in p.stdout


def test_harness_skips_without_data(root, tmp_path):
    p = subprocess.run([sys.executable, str(root / "bench" / "diagnosis_score.py"), "--data",
                        str(tmp_path / "absent")], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and "skipped" in p.stdout


def scored(root, probes, noise, types, tmp_path):
    """The harness's outcomes on seed 0 of a probe directory's base set."""
    scores = tmp_path / "scores.json"
    p = subprocess.run([sys.executable, str(root / "bench" / "diagnosis_score.py"), "--data",
                        str(probes), "--sets", "base", "--seeds", "0", "--noise", noise,
                        "--types", types, "--jobs", "1", "--json", str(scores)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    return json.loads(scores.read_text())


def test_outside_probes_add_their_physics_and_are_not_claimed(root, suite, tmp_path):
    """bench/outside_probes.py on the control: each probe's displacements are the control's
    plus its effect (checked here against the effect's parameters in truth.json, computed
    independently with numpy), at the requested size; the diagnosis claims none of the four
    effects its trend tests were made for (section 2 of docs/diagnosis.md)."""
    np = pytest.importorskip("numpy")
    import stiff

    out = tmp_path / "probes"
    p = subprocess.run([sys.executable, str(root / "bench" / "outside_probes.py"), "--data",
                        str(suite), "--out", str(out), "--sets", "base", "--seeds", "0",
                        "--size", "60"], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    index = json.loads((out / "index.json").read_text())
    assert sorted(e["type"] for e in index) == sorted(
        ["base_shift", "angle_joint", "growth", "warmup", "sensor_level", "sensor_offset",
         "sensor_offset_base"])

    robot = stiff.Robot("rokae")
    base = stiff.Dataset.read(suite / "base" / "none_00" / "calib.csv", robot)
    c = 1 / np.asarray(stiff.identify(robot, base).stiffness)
    jv = robot.jacobian(base.q)[:, :3, :]

    def joints(force):
        """The joints' response to `force` (N x 3) with the compliances the joint model fits the
        control."""
        return np.einsum("nij,nj->ni", jv, np.einsum("nij,ni->nj", jv, force) * c)

    for kind in ("base_shift", "growth", "sensor_level", "sensor_offset"):
        folder = out / "base" / f"{kind}_00"
        probe = stiff.Dataset.read(folder / "calib.csv", robot)
        assert np.array_equal(probe.q, base.q) and np.array_equal(probe.force, base.force)
        added = probe.displacement - base.displacement
        truth = json.loads((folder / "truth.json").read_text())
        assert np.sqrt(np.mean(added ** 2)) == pytest.approx(60e-6, rel=1e-9)
        if kind == "base_shift":
            cb = np.array(truth["effect_parameters"]["C_b_m_per_N"])
            assert np.allclose(cb, cb.T) and np.all(np.linalg.eigvalsh(cb) > 0)
            expect = base.force @ cb.T
        elif kind == "growth":
            pos = robot.tool_pose(base.q)[:, :3, 3]
            expect = pos * len(base) * truth["effect_parameters"]["strain_per_row"]
        elif kind == "sensor_level":
            # The force error -g F, g linear in the level about the calibration's mean level.
            par = truth["effect_parameters"]
            level = np.linalg.norm(base.force, axis=1)
            assert par["reference_level_N"] == pytest.approx(level.mean(), rel=1e-12)
            g = par["sign"] * par["gain_per_relative_level"] * (level / level.mean() - 1)
            expect = joints(-g[:, None] * base.force)
        else:
            # The force error -R b, b constant in the flange frame.
            par = truth["effect_parameters"]
            b = par["offset_N"] * np.array(par["direction"])
            assert np.linalg.norm(par["direction"]) == pytest.approx(1.0, rel=1e-12)
            expect = joints(-robot.tool_pose(base.q)[:, :3, :3] @ b)
        assert np.allclose(added, expect, rtol=0, atol=1e-12)
    rows = scored(root, out, "both", "base_shift,angle_joint,sensor_level,sensor_offset",
                  tmp_path)
    assert len(rows) == 8
    for r in rows:
        assert r["outcome"] == "right", r


def test_form_probes_add_their_physics_and_are_found(root, suite, tmp_path):
    """bench/form_probes.py on the control: its own gravity torques (modified DH read from the
    robot file) agree with stiff's Jacobian, each probe leaves the requested amount after the
    joint compliances, the flange sensor's forces and the tracker's rotation are what
    truth.json says, a pair is the sum of its two forms (a coupling beside an SMR offset seen
    at the moved SMR), a drift over the clock writes the
    loaded readings' times, and the diagnosis names the class of a kinked reducer about the
    gravity preload, of a drift read in reversed order, of one read at irregular times and of
    a reducer hardening with the cube of the load torque, of one stiffer in one direction of
    the load and of a force reading's cross-talk fixed in the base frame, at a 10 um tracker's
    noise
    (docs/diagnosis.md, section 6)."""
    np = pytest.importorskip("numpy")
    import stiff

    fp = bench_module(root, "form_probes")
    for name in ("puma560", "rokae"):  # standard and modified DH, the latter's kept below
        robot = stiff.Robot(name)
        dh, masses, coms = fp.read_dh_robot(root / "examples" / "robots" / f"{name}.yaml")
        q = np.random.default_rng(3).uniform(-1.5, 1.5, (5, robot.dof))
        unit_tool = [0.0] * robot.dof + [2.0]
        tau = fp.gravity_torques(dh, q, unit_tool, [np.zeros(3)] * (robot.dof + 1))
        jv = robot.jacobian(q)[:, :3, :]
        assert np.allclose(tau, np.einsum("nij,i->nj", jv, 2.0 * fp.GRAVITY), atol=1e-12)
    # A link spring at joint 2's origin turning about joint 2's axis is joint 2's compliance.
    f = np.random.default_rng(4).normal(size=(5, 3)) * 30.0
    about_z = np.diag([0.0, 0.0, 1e-5])
    spring = fp.link_spring(dh, q, f, 1, 0.0, about_z)
    tau_f = np.einsum("nij,ni->nj", jv, f)
    assert np.allclose(spring, jv[:, :, 1] * tau_f[:, 1, None] * 1e-5, rtol=0, atol=1e-15)

    out = tmp_path / "forms"
    kinds = ("kinkg23,drift_reversed,force_flange,tracker,coupling24,link_fore,"
             "compensator_lever,kinkg23+drift_reversed,drift_timed,offset_meas,offset_load,"
             "offset_meas+coupling24,cubic23,kink3,force_crosstalk,force_crosstalk_base")
    p = subprocess.run([sys.executable, str(root / "bench" / "form_probes.py"), "--data",
                        str(suite), "--out", str(out), "--sets", "base", "--seeds", "0",
                        "--kinds", kinds], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    base = stiff.Dataset.read(suite / "base" / "none_00" / "calib.csv", robot)
    cols = fp.joint_columns(robot, base.q, base.force)
    for kind in kinds.split(","):
        folder = out / "base" / f"{kind}_00"
        if kind == "offset_meas+coupling24":
            # The coupling's deflection seen at the moved SMR: each joint's column of the
            # point R r off the flange by finite turns of the chain, the torques the file's.
            par = json.loads((folder / "truth.json").read_text())["effect_parameters"]
            r = np.array(par["offset_meas"]["direction_flange"]) * par["offset_meas"]["scale"]
            alone = stiff.Dataset.read(out / "base" / "offset_meas_00" / "calib.csv", robot)
            pair = stiff.Dataset.read(folder / "calib.csv", robot)
            coupled = pair.displacement - alone.displacement
            tau_f = np.einsum("nij,ni->nj", robot.jacobian(base.q)[:, :3, :], base.force)
            h = 1e-6

            def point(qi):
                t = robot.tool_pose(qi)
                return t[:3, 3] + t[:3, :3] @ r

            for i in range(len(base.q)):
                col = [(point(base.q[i] + h * np.eye(robot.dof)[j]) - point(base.q[i])) / h
                       for j in (1, 3)]
                expect = par["coupling24"]["scale"] * (col[0] * tau_f[i, 3] + col[1] * tau_f[i, 1])
                assert np.allclose(coupled[i], expect, rtol=1e-4, atol=1e-12)
            continue
        if "+" in kind:
            # Two forms at once: each drawn as it is alone, the displacements their sum.
            pair = stiff.Dataset.read(folder / "calib.csv", robot).displacement
            parts = [stiff.Dataset.read(out / "base" / f"{k}_00" / "calib.csv",
                                        robot).displacement - base.displacement
                     for k in kind.split("+")]
            assert np.allclose(pair, base.displacement + sum(parts), rtol=0, atol=1e-12)
            truth = json.loads((folder / "truth.json").read_text())
            assert truth["expected"]["effects"] == [fp.KINDS[k] for k in kind.split("+")]
            continue
        probe = stiff.Dataset.read(folder / "calib.csv", robot)
        truth = json.loads((folder / "truth.json").read_text())
        assert truth["expected"]["effects"] == [fp.KINDS[kind]]
        added = (probe.displacement - base.displacement).reshape(-1)
        if kind in ("force_flange", "force_crosstalk", "force_crosstalk_base"):
            # The sensor's reading A F (A in the sensor's frame, or the base's), the arm's
            # displacements those of the true force.
            assert np.array_equal(probe.displacement, base.displacement)
            par = truth["effect_parameters"]
            if kind == "force_flange":
                a = (fp.rodrigues(np.array(par["rotation_rad"])) @
                     np.diag(1 + np.array(par["gains"])))
            else:
                x = np.array(par["X"])
                assert np.allclose(x, x.T) and np.all(np.diag(x) == 0)
                assert np.all((np.abs(x[np.triu_indices(3, 1)]) >= 0.08) &
                              (np.abs(x[np.triu_indices(3, 1)]) <= 0.12))
                a = np.eye(3) + x
            rot = (robot.tool_pose(base.q)[:, :3, :3] if kind != "force_crosstalk_base"
                   else np.broadcast_to(np.eye(3), (len(base.q), 3, 3)))
            expect = np.einsum("nij,jk,nlk,nl->ni", rot, a, rot, base.force)
            assert np.allclose(probe.force, expect, atol=0.0051)  # written to 0.01 N
            continue
        assert np.array_equal(probe.force, base.force)
        if kind == "drift_timed":
            # Along one direction, and the loaded readings' times written, rising, with the
            # pause: one wait of 10 min or more (the others 5 s + a mean of 25 s).
            direction = np.array(truth["effect_parameters"]["direction"])
            moved = added.reshape(-1, 3)
            assert np.allclose(np.cross(moved, direction), 0.0, atol=1e-15)
            lines = [x for x in (folder / "calib.csv").read_text().splitlines()
                     if not x.startswith("#")]
            assert lines[0].split(",")[-1] == "t_s"
            control = [x for x in (suite / "base" / "none_00" / "calib.csv").read_text()
                       .splitlines() if not x.startswith("#")]
            assert "t_s" not in control[0].split(",")
            t = np.array([float(x.split(",")[-1]) for x in lines[1:]])
            assert len(t) == len(moved) and np.all(np.diff(t) >= 5.0 - 0.05)
            assert (np.diff(t) >= 600.0).sum() == 1
        if kind.startswith("offset_"):
            # The load turns the joints by dq = C J^T (F, M); a point off the flange by R r moves
            # with the flange's turn, a load off it adds the moment (R r) x F. Checked against
            # finite turns of the chain (tool_pose only, not the Jacobian's rotation rows).
            par = truth["effect_parameters"]
            r = np.array(par["direction_flange"]) * par["scale"]
            comp = 1.0 / np.asarray(stiff.identify(robot, base).stiffness)
            comp[~np.isfinite(comp)] = 0.0
            jac = robot.jacobian(base.q)
            rot = robot.tool_pose(base.q)[:, :3, :3]
            h = 1e-3
            for i in range(len(base.q)):
                if kind == "offset_meas":
                    dq = comp * (jac[i, :3].T @ base.force[i])
                    turned = robot.tool_pose(base.q[i] + h * dq)[:3, :3] @ rot[i].T
                    theta = np.array([turned[2, 1], turned[0, 2], turned[1, 0]]) / h
                    expect = np.cross(theta, rot[i] @ r)
                else:
                    dq = comp * (jac[i, 3:].T @ np.cross(rot[i] @ r, base.force[i]))
                    expect = (robot.tool_pose(base.q[i] + h * dq)[:3, 3] -
                              robot.tool_pose(base.q[i])[:3, 3]) / h
                assert np.allclose(added.reshape(-1, 3)[i], expect, rtol=2e-3, atol=1e-9)
        if kind == "tracker":
            angle = np.deg2rad(truth["effect_parameters"]["angle_deg"])
            r = fp.rodrigues(np.array(truth["effect_parameters"]["axis"]) * angle)
            assert np.allclose(probe.displacement, base.displacement @ r.T, rtol=0, atol=1e-10)
            continue
        # What the joint compliances leave of it: the requested 40 um per axis (a coupling
        # less when that would take a compliance matrix that is not positive definite).
        left = fp.rms_left(cols, added)
        if truth["effect_parameters"].get("rho", 0.0) < 0.8 - 1e-9:
            assert left == pytest.approx(40e-6, rel=1e-6)
        else:
            assert left < 40e-6
    rows = scored(root, out, "given",
                  "kinkg23,drift_reversed,drift_timed,cubic23,kink3,force_crosstalk_base",
                  tmp_path)
    assert len(rows) == 6
    for r in rows:
        assert r["outcome"] == "right" and r["ratio"] < 1.25, r


def test_thermal_growth_of_another_arm_is_not_claimed(root, tmp_path):
    """The PUMA 560's links growing between the two readings (d = eps P, bench/outside_probes.py
    `growth`), no noise statement: `complementary`, whose one column follows the position on
    this arm, was claimed until the thermal_growth trend test (docs/diagnosis.md, sections 2
    and 6); now the residual's trend with the position refutes it."""
    data = tmp_path / "controls"
    folder = data / "puma" / "none_01"
    folder.mkdir(parents=True)
    for csv, count, seed in (("calib.csv", 60, 101), ("valid.csv", 40, 201)):
        assert main(["simulate", "--robot", "puma560", "--count", str(count), "--seed", str(seed),
                     "--stiffness", "60000,40000,30000,8000,6000,4000", "--tracker-sigma-um",
                     "10", "--tracker-ppm", "5", "--force-relative", "0.01",
                     "--force-absolute-n", "0.3", "-o", str(folder / csv)]) == 0
    (folder / "truth.json").write_text(json.dumps({"type": "none",
                                                   "expected": {"verdict": "adequate"}}))
    (data / "index.json").write_text(json.dumps([{"path": "puma/none_01", "type": "none"}]))
    out = tmp_path / "probes"
    p = subprocess.run([sys.executable, str(root / "bench" / "outside_probes.py"), "--data",
                        str(data), "--out", str(out), "--sets", "puma", "--seeds", "1",
                        "--kinds", "growth", "--robot", "puma560"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    scores = tmp_path / "scores.json"
    p = subprocess.run([sys.executable, str(root / "bench" / "diagnosis_score.py"), "--data",
                        str(out), "--sets", "puma", "--seeds", "1", "--noise", "hidden",
                        "--jobs", "1", "--robot", str(root / "examples" / "robots" /
                                                     "puma560.yaml"), "--json", str(scores)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    rows = json.loads(scores.read_text())
    assert len(rows) == 1 and rows[0]["outcome"] == "right", rows


@pytest.mark.parametrize("script", ["outside_probes.py", "form_probes.py"])
def test_probes_refuse_an_unknown_kind(root, suite, tmp_path, script):
    p = subprocess.run([sys.executable, str(root / "bench" / script), "--data", str(suite),
                        "--out", str(tmp_path / "x"), "--kinds", "pedestal"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "unknown kind 'pedestal'" in p.stderr
    assert not (tmp_path / "x").exists()


def test_arm_probes_make_scenarios_the_harness_reads(root, tmp_path):
    """bench/arm_probes.py on a UR10: the coupling is drawn at the asked size (55 um RMS per
    axis on the calibration rows, against about 20 um of noise) and named, the control stays
    `adequate`; the IRB 120's file has no masses, so its backlash is skipped with a message."""
    out = tmp_path / "arms"
    p = subprocess.run([sys.executable, str(root / "bench" / "arm_probes.py"), "--out", str(out),
                        "--robots", "ur10,abb_irb120", "--kinds", "none,coupling,backlash",
                        "--seeds", "0"], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert "abb_irb120: backlash skipped" in p.stderr
    index = json.loads((out / "abb_irb120" / "index.json").read_text())
    assert [e["type"] for e in index] == ["none", "coupling"]
    import stiff

    ur10 = out / "ur10" / "base"
    truth = json.loads((ur10 / "coupling_00" / "truth.json").read_text())
    noisy = stiff.Dataset.read(ur10 / "coupling_00" / "calib.csv").displacement
    control = stiff.Dataset.read(ur10 / "none_00" / "calib.csv").displacement
    # Same poses and noise draw in both files: the difference is the effect alone.
    assert np.sqrt(np.mean((noisy - control) ** 2)) == pytest.approx(55e-6, rel=0.05)
    assert 15 < truth["true_class_refit_valid_um"]["axis_um"] < 30
    scores = tmp_path / "scores.json"
    p = subprocess.run([sys.executable, str(root / "bench" / "diagnosis_score.py"), "--data",
                        str(out / "ur10"), "--robot", "ur10", "--sets", "base", "--seeds", "0",
                        "--noise", "given", "--jobs", "1", "--json", str(scores)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    rows = {r["type"]: r for r in json.loads(scores.read_text())}
    assert rows["none"]["outcome"] == "right" and rows["coupling"]["outcome"] == "right", rows
    assert rows["coupling"]["final"] == ["coupling"]
