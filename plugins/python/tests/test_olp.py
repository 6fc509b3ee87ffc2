"""Program filters (KRL, RAPID, Fanuc LS), the FilterTarget call, the Kienzle model and the
RoboDK post-processor wrapper (docs/olp.md). RoboDK's robomath is the independent oracle of
each vendor's pose convention."""
import math
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

import stiff
from stiff import olp
from stiff.olp import frames as fr
from stiff.olp.cutting import MATERIALS, KienzleMaterial, MillingCut, mean_chip_thickness, mean_force
from stiff.olp.program import tool_points

rm = pytest.importorskip("robodk.robomath")
STIFF = [sys.executable, "-m", "stiff.cli"]
WP = (420.0, -100.0, -180.0, 15.0, 0.0, 0.0)
TOOL = (0.0, 0.0, 120.0, 0.0, 0.0, 0.0)


def mat(m) -> np.ndarray:
    t = np.array(m.rows, dtype=float)
    t[:3, 3] *= 1e-3
    return t


@pytest.fixture(scope="module")
def robot(rokae_path):
    return stiff.Robot(rokae_path)


@pytest.fixture(scope="module")
def model(robot, tmp_path_factory):
    """Joint compliances identified from noise-free simulated data (the fit the CLI uses)."""
    data = stiff.simulate(robot, stiff.random_design(robot, count=40, seed=3),
                          stiffness=[4.0e5, 3.0e5, 2.0e5, 8.0e4, 6.0e4, 4.0e4], tracker_sigma_m=0.0)
    fit = stiff.identify(robot, data)
    path = tmp_path_factory.mktemp("fit") / "fit.json"
    fit.write(path)
    return stiff.Model(robot, fit), path


@pytest.fixture()
def programs(root, tmp_path):
    dst = tmp_path / "programs"
    shutil.copytree(root / "examples" / "programs", dst)
    return dst


# ------------------------------------------------------------------ conventions
def test_pose_conventions_match_robomath():
    rng = np.random.default_rng(2)
    for _ in range(200):
        x = list(rng.uniform(-900, 900, 3)) + list(rng.uniform(-179, 179, 3))
        x[4] = rng.uniform(-89, 89)
        k = rm.KUKA_2_Pose(x)
        assert np.allclose(fr.kuka_to_pose(*x), mat(k), atol=1e-12)
        assert np.allclose(fr.pose_to_kuka(mat(k)), rm.Pose_2_KUKA(k), atol=1e-9)
        f = rm.Fanuc_2_Pose(x)
        assert np.allclose(fr.fanuc_to_pose(*x), mat(f), atol=1e-12)
        assert np.allclose(fr.pose_to_fanuc(mat(f)), rm.Pose_2_Fanuc(f), atol=1e-9)
        abb = rm.Pose_2_ABB(k)
        xyz, q = fr.pose_to_abb(mat(k), abb[3:])
        assert np.allclose(q, abb[3:], atol=1e-12) and np.allclose(xyz, abb[:3], atol=1e-9)
        assert np.allclose(fr.abb_to_pose(abb[:3], abb[3:]), mat(k), atol=1e-12)


# ---------------------------------------------------------------- filter_target
def test_filter_target_makes_the_loaded_tcp_reach_the_target(robot, model):
    m, _ = model
    base = fr.kuka_to_pose(*WP)
    tool = fr.kuka_to_pose(0, 10, 120, 0, 15, 0)
    pose = fr.kuka_to_pose(20, 10, -2, 30, 10, 175)
    w = np.array([40.0, -60.0, -150.0, 0.5, 0.0, 1.0])
    res = olp.filter_target(m, pose, np.radians([0, 10, -20, 0, -60, 0]), w, base, tool)
    assert res.status == 0
    # Independent check: the model's measured-point deflection at q_cmd under the wrench moved
    # to the load point, carried rigidly to the TCP.
    mp, lp = tool_points(robot)
    t_mp = robot.tool_pose(res.q)
    flange = t_mp.copy()
    flange[:3, 3] -= t_mp[:3, :3] @ mp
    tcp = flange @ tool
    rb = base[:3, :3]
    f = rb @ w[:3]
    # In the loaded state the tool is at the target: the lever of the moment is taken there.
    tcp_nom = base @ pose
    fl_nom = tcp_nom @ np.linalg.inv(tool)
    load = fl_nom[:3, :3] @ lp + fl_nom[:3, 3]
    wc = np.concatenate([f, rb @ w[3:] + np.cross(tcp_nom[:3, 3] - load, f)])
    d = m.predict(res.q, wc).ravel()
    r = d[3:]
    a = np.linalg.norm(r)
    kx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]]) / a
    exp = np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx
    loaded_tcp = t_mp[:3, 3] + d[:3] + exp @ (tcp[:3, 3] - t_mp[:3, 3])
    nominal = (base @ pose)[:3, 3]
    assert np.linalg.norm(loaded_tcp - nominal) < 1e-9
    assert np.allclose(base @ res.pose, tcp, atol=1e-12)
    assert np.linalg.norm(d[:3]) > 50e-6  # a real deflection was compensated


def test_filter_target_flags_unreachable(model):
    m, _ = model
    far = fr.kuka_to_pose(3000, 0, 0, 0, 0, 180)
    res = olp.filter_target(m, far, None, [0, 0, -100])
    assert res.status & stiff.compensate.POINT_UNREACHABLE
    assert np.array_equal(res.pose, far)


# --------------------------------------------------------------- golden files
def _masked(text: str, spans) -> str:
    out, pos = [], 0
    for a, b in sorted(spans):
        out += [text[pos:a], "#"]
        pos = b
    return "".join(out + [text[pos:]])


def _oracle_pose(fmt_name, values):
    if fmt_name == "KUKA KRL":
        return mat(rm.KUKA_2_Pose(values))
    if fmt_name == "Yaskawa JBI":
        return mat(rm.Motoman_2_Pose(values[:6]))
    if fmt_name == "ABB RAPID":
        t = mat(rm.quaternion_2_pose(values[3:7]))
        t[:3, 3] = np.array(values[:3]) * 1e-3
        return t
    return mat(rm.Fanuc_2_Pose(values))


def _check_program(robot, m, src_path, out_dir, result, **frames):
    prog = result.program
    again = olp.read_program(out_dir / src_path.name, **frames)
    assert len(again.targets) == len(prog.targets)
    for key in prog.texts:
        spans_in = [(a, b) for t in prog.targets for (f, a, b) in t.spans + t.config_spans
                    if f == key]
        spans_out = [(a, b) for t in again.targets for (f, a, b) in t.spans + t.config_spans
                     if f == key]
        # every byte outside the target numbers is unchanged
        assert _masked(prog.texts[key], set(spans_in)) == _masked(again.texts[key], set(spans_out))
        changed = [i for i, (x, y) in enumerate(zip(prog.texts[key].splitlines(),
                                                   again.texts[key].splitlines())) if x != y]
        assert all(re.search(r"\d", prog.texts[key].splitlines()[i]) for i in changed)
    mp, lp = tool_points(robot)
    worst, biggest = 0.0, 0.0
    for t0, t1, rep in zip(prog.targets, again.targets, result.targets):
        assert rep.status & 2 == 0
        base, tool = t0.base, t0.tool
        if t0.joint:
            q = np.radians(t0.values)
            t_mp = robot.tool_pose(q)
            fl = t_mp.copy()
            fl[:3, 3] -= t_mp[:3, :3] @ mp
            nominal = np.linalg.inv(base) @ fl @ tool
            q_cmd = np.radians(t1.values)
        else:
            nominal = _oracle_pose(prog.fmt.name, t0.values)
            q_cmd = rep.q_cmd
        if t1.joint:
            t_mp = robot.tool_pose(q_cmd)
            fl = t_mp.copy()
            fl[:3, 3] -= t_mp[:3, :3] @ mp
            written = np.linalg.inv(base) @ fl @ tool
        else:
            written = _oracle_pose(prog.fmt.name, t1.values)
        # predicted TCP deflection at the commanded joints (independent of the library's
        # frame handling): the measured point's deflection carried rigidly to the TCP
        t_mp = robot.tool_pose(q_cmd)
        fl = t_mp.copy()
        fl[:3, 3] -= t_mp[:3, :3] @ mp
        tcp = (base @ written)[:3, 3]
        rb = base[:3, :3]
        f = rb @ rep.wrench[:3]
        fl_nom = base @ nominal @ np.linalg.inv(tool)  # loaded state: the tool at the target
        load = fl_nom[:3, :3] @ lp + fl_nom[:3, 3]
        wc = np.concatenate([f, rb @ rep.wrench[3:] + np.cross((base @ nominal)[:3, 3] - load, f)])
        d = m.predict(q_cmd, wc).ravel()
        r = d[3:]
        a = max(np.linalg.norm(r), 1e-300)
        kx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]]) / a
        exp = np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx
        delta = d[:3] + (exp - np.eye(3)) @ (tcp - t_mp[:3, 3])
        # written = nominal - predicted deflection (reference-frame components)
        err = (base @ written)[:3, 3] - ((base @ nominal)[:3, 3] - delta)
        worst = max(worst, float(np.linalg.norm(err)))
        biggest = max(biggest, float(np.linalg.norm(delta)))
    assert worst < 1e-9, worst
    assert biggest > 20e-6  # the program really was corrected
    return again


def test_krl_golden(robot, model, programs, tmp_path):
    m, _ = model
    src = programs / "kuka" / "slot.src"
    prog = olp.read_program(src)
    kinds = [(t.motion, t.joint, t.name) for t in prog.targets]
    assert kinds[0] == ("PTP", True, "XHOME") and ("LIN", False, "inline") in kinds
    assert prog.targets[1].load.mass == 4.5 and abs(prog.targets[1].tool[2, 3] - 0.12) < 1e-15
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[0, 80, -120], tool_weight=True))
    out = tmp_path / "out"
    res.write(out)
    again = _check_program(robot, m, src, out, res)
    # air (PTP) moves carry only the tool weight
    for t, rep in zip(prog.targets, res.targets):
        weight = 4.5 * 9.80665
        if t.motion == "PTP":
            assert abs(np.linalg.norm(rep.wrench[:3]) - weight) < 1e-9
        else:
            assert np.allclose(rep.wrench[:3], [0, 80, -120 - weight], atol=1e-9)
    # the .dat's S and T are unchanged (the compensation keeps the configuration)
    assert [t.config for t in again.targets] == [t.config for t in prog.targets]
    assert (out / "slot.dat").read_bytes().count(b"\r\n") == (src.with_suffix(".dat")).read_bytes().count(b"\r\n")


def test_krl_binary_status_and_turn_are_kept(robot, model, programs, tmp_path):
    """S 'B010' / T 'B101011' (binary strings) stay binary strings of the same width."""
    m, _ = model
    dat = programs / "kuka" / "slot.dat"
    dat.write_text(dat.read_text(encoding="latin-1").replace("S 2,T 43", "S 'B00010',T 'B101011'"),
                   encoding="latin-1", newline="")
    prog = olp.read_program(programs / "kuka" / "slot.src")
    assert prog.targets[1].config == (2, 43)
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[0, 80, -120]))
    (tmp_path / "o").mkdir()
    res.write(tmp_path / "o")
    text = (tmp_path / "o" / "slot.dat").read_text(encoding="latin-1")
    assert text.count("S 'B00010',T 'B101011'") == 8
    _check_program(robot, m, programs / "kuka" / "slot.src", tmp_path / "o", res)


def test_rapid_golden_with_milling_model(robot, model, programs, tmp_path):
    m, _ = model
    src = programs / "abb" / "Slot.mod"
    prog = olp.read_program(src)
    assert prog.targets[0].motion == "MoveAbsJ" and prog.targets[0].joint
    cut = MillingCut(10.0, 2, 0.05, 5.0, 2.0)
    res = olp.filter_program(prog, m, olp.WrenchSpec(milling=(MATERIALS["C45"], cut),
                                                     tool_weight=True))
    out = tmp_path / "out"
    res.write(out)
    _check_program(robot, m, src, out, res)
    f_mill = np.linalg.norm(mean_force(MATERIALS["C45"], cut)[:2])
    forces = [np.linalg.norm(r.wrench[:2]) for r in res.targets]
    moves = [t.motion for t in prog.targets]
    for mv, fn, t in zip(moves, forces, prog.targets):
        if mv == "MoveL" and t.name not in ("p20",):
            assert fn > 0.5 * f_mill   # cutting moves carry the milling force
        if mv in ("MoveJ", "MoveAbsJ"):
            assert fn < 1e-9           # air moves: weight only (vertical)


def test_fanuc_golden(robot, model, programs, tmp_path):
    m, _ = model
    src = programs / "fanuc" / "slot.ls"
    frames = dict(frames={1: fr.fanuc_to_pose(*WP)}, tools={1: fr.fanuc_to_pose(*TOOL)})
    prog = olp.read_program(src, **frames)
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[30, 0, -100]))
    out = tmp_path / "out"
    res.write(out)
    _check_program(robot, m, src, out, res, **frames)
    with pytest.raises(olp.FilterError, match="UF 1"):
        olp.read_program(src)


def test_jbi_golden(robot, model, programs, tmp_path):
    m, _ = model
    src = programs / "yaskawa" / "SLOT.JBI"
    frames = dict(frames={1: fr.fanuc_to_pose(*WP)}, tools={1: fr.fanuc_to_pose(*TOOL)})
    prog = olp.read_program(src, **frames)
    assert [t.motion for t in prog.targets][:2] == ["MOVJ", "MOVL"]
    res = olp.filter_program(prog, m, olp.WrenchSpec(
        force=[20, 60, -100], tool_load=olp.ToolLoad(4.5, np.array([0, 0, 0.06])),
        tool_weight=True))
    out = tmp_path / "out"
    res.write(out)
    _check_program(robot, m, src, out, res, **frames)
    assert (out / "SLOT.JBI").read_bytes().count(b"\r\n") == src.read_bytes().count(b"\r\n")
    with pytest.raises(olp.FilterError, match="SLOT.JBI:10: C00000 is in user frame 1"):
        olp.read_program(src)


def test_feed_per_tooth_follows_the_programmed_speed(model, programs):
    """KRL $VEL.CP = 0.02 m/s at 12000 1/min with 2 teeth: f_z = 0.05 mm whatever --cut says."""
    m, _ = model
    prog = olp.read_program(programs / "kuka" / "slot.src")
    material = MATERIALS["C45"]
    fast = olp.filter_program(prog, m, olp.WrenchSpec(
        milling=(material, MillingCut(10.0, 2, 0.2, 5.0, 2.0)), spindle_rpm=12000.0))
    direct = olp.filter_program(prog, m, olp.WrenchSpec(
        milling=(material, MillingCut(10.0, 2, 0.05, 5.0, 2.0))))
    w1 = np.array([r.wrench for r in fast.targets])
    w2 = np.array([r.wrench for r in direct.targets])
    assert np.abs(w1).max() > 50 and np.allclose(w1, w2, atol=1e-9)


def test_wrong_configuration_and_bad_programs_are_clear_errors(model, programs, tmp_path):
    m, _ = model
    dat = programs / "kuka" / "slot.dat"
    text = dat.read_text(encoding="latin-1")
    bad = re.sub(r"(XP2=\{[^}]*S )(\d+)", lambda g: g.group(1) + str(int(g.group(2)) ^ 1), text)
    dat.write_text(bad, encoding="latin-1", newline="")
    with pytest.raises(olp.FilterError, match=r"slot.src:\d+: target XP2: no inverse kinematics"):
        olp.filter_program(olp.read_program(programs / "kuka" / "slot.src"), m, olp.WrenchSpec())
    src = programs / "kuka" / "slot.src"
    src.write_text(src.read_text(encoding="latin-1").replace("$BASE = {X", "$BASE = BASE_DATA[3]\r\n;{X"),
                   encoding="latin-1", newline="")
    with pytest.raises(olp.FilterError, match=r"slot.src:8: BASE_DATA\[3\].*--frame 3"):
        olp.read_program(src)
    p = tmp_path / "rel.src"
    p.write_text("DEF rel()\nLIN_REL {X 10}\nEND\n")
    with pytest.raises(olp.FilterError, match="rel.src:2: LIN_REL: relative"):
        olp.read_program(p)
    p = tmp_path / "part.src"
    p.write_text("DEF part()\nLIN {X 10, Y 5}\nEND\n")
    with pytest.raises(olp.FilterError, match="partial position"):
        olp.read_program(p)


def test_unreachable_targets_are_flagged_and_kept(model, tmp_path):
    m, _ = model
    p = tmp_path / "far.src"
    text = ("DEF far()\n$BASE = {X 420.0, Y -100.0, Z -180.0, A 15.0, B 0.0, C 0.0}\n"
            "LIN {X 0.0, Y 0.0, Z -2.0, A 0.0, B 10.0, C 180.0}\n"
            "LIN {X 3000.0, Y 0.0, Z -2.0, A 0.0, B 10.0, C 180.0} ; out of reach\nEND\n")
    p.write_text(text)
    res = olp.filter_program(olp.read_program(p), m, olp.WrenchSpec(force=[0, 0, -100]))
    assert [r.flags() for r in res.targets] == ["ok", "unreachable"]
    assert res.summary()["problems"] == [(2, 4, "unreachable")]
    out = res.texts["src"].splitlines()
    assert out[3] == text.splitlines()[3] and out[2] != text.splitlines()[2]


def test_filter_never_overwrites_the_input(model, programs):
    m, _ = model
    src = programs / "abb" / "Slot.mod"
    before = src.read_bytes()
    res = olp.filter_program(olp.read_program(src), m, olp.WrenchSpec(force=[0, 0, -50]))
    with pytest.raises(olp.FilterError, match="overwrite the input"):
        res.write(src.parent)
    assert src.read_bytes() == before


def test_cli_filter(model, programs, tmp_path):
    _, fit = model
    out = tmp_path / "o"
    r = subprocess.run(STIFF + ["filter", "--robot", "rokae", "--fit", str(fit),
                                str(programs / "fanuc" / "slot.ls"), "--frame",
                                "1=" + ",".join(map(str, WP)), "--tool", "1=0,0,120,0,0,0",
                                "--material", "AlMg3", "--cut", "10,3,0.08,5,3",
                                "-o", str(out), "--report", str(tmp_path / "r.csv")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "Fanuc LS: 8 targets" in r.stdout and (out / "slot.ls").exists()
    assert (tmp_path / "r.csv").read_text().startswith("target,file,line")
    r = subprocess.run(STIFF + ["filter", "--robot", "rokae", "--fit", str(fit),
                                str(programs / "fanuc" / "slot.ls"), "-o", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "UF 1" in r.stderr and "Traceback" not in r.stderr


# ---------------------------------------------------------------------- Kienzle
def test_kienzle_linear_limit_matches_altintas_closed_form():
    """m_c = 0 is the linear force model whose tooth-period mean has a closed form
    (Altintas, Manufacturing Automation, eq. 2.x)."""
    kt, kr = 1500.0, 0.35
    mat_ = KienzleMaterial(kt, 0.0)
    for down in (True, False):
        for ae in (1.0, 4.0, 10.0):
            cut = MillingCut(10.0, 3, 0.1, ae, 2.0, down, kr)
            a, b = cut.arc()
            z, ap, fz = 3, 2.0, 0.1
            fx = lambda p: kt * math.cos(2 * p) - kr * kt * (2 * p - math.sin(2 * p))
            fy = lambda p: kt * (2 * p - math.sin(2 * p)) + kr * kt * math.cos(2 * p)
            ref = z * ap * fz / (8 * math.pi) * np.array([fx(b) - fx(a), fy(b) - fy(a)])
            assert np.allclose(mean_force(mat_, cut)[:2], ref, rtol=1e-6)


def test_kienzle_power_matches_handbook_formula():
    """Cutting power P = k_c(h_m) a_p a_e v_f (the handbook formula with the Kienzle constants
    of the material) against the tooth-period mean torque of the model: they differ only by
    the curvature of h^(1-m_c) over the arc (a few percent)."""
    for name, material in MATERIALS.items():
        cut = MillingCut(16.0, 4, 0.1, 8.0, 3.0, True, 0.0)
        n = 3000 / 60.0  # rev/s
        vf = cut.feed_per_tooth * cut.teeth * n  # mm/s
        hm = mean_chip_thickness(cut)
        p_handbook = material.kc11 * hm ** -material.mc * cut.depth * cut.width * vf * 1e-3  # W
        a, b = cut.arc()
        phi = np.linspace(a, b, 20001)
        ft = cut.depth * material.kc11 * (cut.feed_per_tooth * np.sin(phi)) ** (1 - material.mc)
        torque = cut.teeth / (2 * math.pi) * np.trapezoid(ft, phi) * cut.diameter / 2 * 1e-3
        assert abs(torque * 2 * math.pi * n / p_handbook - 1) < 0.05, name
        # the model's resolved force: with K_r = 0 its magnitude is set by the same integral
        f = mean_force(material, cut)
        assert 0 < np.linalg.norm(f) <= cut.teeth / (2 * math.pi) * np.trapezoid(ft, phi)


# ---------------------------------------------------------------------- RoboDK
class _TestPost:
    """A minimal post-processor written for this test: KRL-like lines via robomath."""

    def __init__(self):
        self.lines = []

    def setFrame(self, pose, frame_id=None, frame_name=None):
        self.lines.append("BASE " + " ".join(f"{v:.6f}" for v in rm.Pose_2_KUKA(pose)))

    def setTool(self, pose, tool_id=None, tool_name=None):
        self.lines.append("TOOL " + " ".join(f"{v:.6f}" for v in rm.Pose_2_KUKA(pose)))

    def setSpeed(self, speed_mms):
        self.lines.append(f"VEL {speed_mms}")

    def RunCode(self, code, is_function_call=False):
        self.lines.append(f"CODE {code}")

    def MoveJ(self, pose, joints, conf_RLF=None):
        self.lines.append("PTP " + " ".join(f"{v:.9f}" for v in rm.Pose_2_KUKA(pose)) +
                          " | " + " ".join(f"{v:.9f}" for v in (joints or [])))

    def MoveL(self, pose, joints, conf_RLF=None):
        self.lines.append("LIN " + " ".join(f"{v:.9f}" for v in rm.Pose_2_KUKA(pose)) +
                          " | " + " ".join(f"{v:.9f}" for v in (joints or [])))

    def ProgFinish(self, name):
        self.lines.append("END")


def test_robodk_wrapper_drives_a_test_post(robot, model):
    m, _ = model
    from stiff.olp.robodk_post import CompensatingPost, compensating_post_class

    material, cut = MATERIALS["C45"], MillingCut(10.0, 2, 0.05, 5.0, 2.0)
    RobotPost = compensating_post_class(_TestPost, m, milling=(material, cut))
    wrapped = RobotPost()   # what RoboDK does with a post file's RobotPost
    post = wrapped._post
    frame, tool = rm.KUKA_2_Pose(list(WP)), rm.KUKA_2_Pose(list(TOOL))
    wrapped.setFrame(frame)
    wrapped.setTool(tool)
    path = [("J", (0, 0, 50)), ("L", (0, 0, -2)), ("L", (40, 0, -2)), ("L", (40, 30, -2)),
            ("J", (40, 30, 50))]
    seed = np.radians([0, 10, -20, 0, -60, 0])
    for i, (kind, p) in enumerate(path):
        if i == 1:
            wrapped.RunCode("M3 S6000")
            wrapped.setSpeed(10.0)
        if i == 4:
            wrapped.RunCode("M5")
        pose = rm.KUKA_2_Pose(list(p) + [0, 0, 180])
        mp = mat(frame) @ mat(pose) @ np.linalg.inv(mat(tool))
        seed = stiff.inverse_kinematics(robot, mp, seed)[0]
        (wrapped.MoveJ if kind == "J" else wrapped.MoveL)(pose, list(np.degrees(seed)), [0, 0, 0])
    wrapped.ProgFinish("slot")  # forwarded by __getattr__
    moves = [ln for ln in post.lines if ln.startswith(("PTP", "LIN"))]
    assert len(moves) == 5 and post.lines[-1] == "END"
    assert "CODE M3 S6000" in post.lines
    # feed per tooth from setSpeed and the spindle: 10 mm/s * 60 / (6000 * 2) = 0.05 mm
    f_expected = np.linalg.norm(mean_force(material, cut)[:2])
    forces = [np.linalg.norm(mo.wrench[:3]) for mo in wrapped.motions]
    assert forces[0] == 0 and forces[4] == 0        # air moves
    assert forces[1] == 0                           # plunge: no feed direction in the plane
    assert abs(forces[2] - f_expected) < 1e-9 * f_expected and forces[3] > 0
    # what the post wrote is the compensated pose (robomath reading of the written numbers)
    for line, mo, (_, p) in zip(moves, wrapped.motions, path):
        vals = [float(v) for v in line.split("|")[0].split()[1:]]
        written = mat(rm.KUKA_2_Pose(vals))
        assert np.linalg.norm(written[:3, 3] - mo.pose_cmd[:3, 3]) < 1e-11
        joints = np.radians([float(v) for v in line.split("|")[1].split()])
        assert np.allclose(joints, mo.q_cmd, atol=1e-10)
        nominal = np.array(p) * 1e-3
        if np.linalg.norm(mo.wrench) > 0:
            assert np.linalg.norm(written[:3, 3] - nominal) > 10e-6
        else:
            assert np.linalg.norm(written[:3, 3] - nominal) < 1e-9
    # a force table (3 values: a pure force) and a tool weight instead of the milling model
    load = olp.ToolLoad(5.0, np.array([0.0, 0.0, 0.05]))
    wrapped = CompensatingPost(_TestPost(), m, force_file={2: [0, 0, -90]}, tool_load=load)
    wrapped.setFrame(frame)
    wrapped.setTool(tool)
    for kind, p in path:
        (wrapped.MoveJ if kind == "J" else wrapped.MoveL)(
            rm.KUKA_2_Pose(list(p) + [0, 0, 180]), None)
    weight = 5.0 * 9.80665 * (np.linalg.inv(mat(frame))[:3, :3] @ [0, 0, -1])
    w = np.array([mo.wrench for mo in wrapped.motions])
    assert np.allclose(w[0, :3], weight) and np.allclose(w[1, :3], weight)
    assert np.allclose(w[2, :3], weight + [0, 0, -90])   # second MoveL: the table's force


# ------------------------------------------------------------- tool orientation
def test_tool_rotation_never_worse_on_the_virtual_robot(robot, tmp_path):
    """A tilted spindle (tool axis not the flange axis): rotating about the tool axis moves the
    whole arm. The chosen rotation must not raise the predicted or the simulated (virtual robot,
    its truth file) deviation at any target, stay within the limits, rotate smoothly and keep
    the joints within their limits and the configuration."""
    from stiff.olp.orient import optimise_tool_rotation, rotate_about_tool_axis
    from stiff.olp.target import ArmGeometry, Configuration, JointMap

    truth = tmp_path / "truth.yaml"
    truth.write_text("stiffness_Nm_per_rad: [50914, 16382, 31311, 7791.1, 5613.6, 4000]\n")
    data = stiff.simulate(robot, stiff.random_design(robot, count=40, seed=5), truth=truth,
                          tracker_sigma_m=0.0)
    m = stiff.Model(robot, stiff.identify(robot, data))
    base = fr.kuka_to_pose(*WP)
    tool = fr.kuka_to_pose(80.0, 0.0, 110.0, 0.0, 30.0, 0.0)  # angled spindle head
    poses = [fr.kuka_to_pose(x, y, -2.0, 0, 0, 180)
             for x, y in [(0, 0), (20, 0), (40, 0), (60, 0), (60, 20), (60, 40), (40, 40), (20, 40)]]
    wrench = np.tile([60.0, -40.0, -120.0, 0, 0, 0], (len(poses), 1))
    geo = ArmGeometry(robot)
    key = lambda q: Configuration.of(geo, q, JointMap()).abb_confdata()
    rot = optimise_tool_rotation(m, poses, wrench, base, tool, np.radians([0, 10, -20, 0, -60, 0]),
                                 limit_deg=90, resolution_deg=5, max_step_deg=10, key=key)
    assert np.all(np.abs(rot.psi) <= math.radians(90) + 1e-12)
    assert np.all(np.abs(np.diff(rot.psi)) <= math.radians(10) + 1e-9)
    assert np.all(rot.deflection <= rot.nominal * (1 + 1e-12))
    lo, hi = robot.limits
    assert np.all(rot.q >= lo - 1e-12) and np.all(rot.q <= hi + 1e-12)
    # simulated deviation (uncompensated, the truth's deflection) at both orientations
    mp, lp = tool_points(robot)

    def simulated(psis):
        out = []
        for pose, psi, w in zip(poses, psis, wrench):
            p = rotate_about_tool_axis(pose, psi)
            q = olp.filter_target(m, p, rot.q[0], None, base, tool).q
            t_mp = robot.tool_pose(q)
            fl = t_mp.copy()
            fl[:3, 3] -= t_mp[:3, :3] @ mp
            tcp = fl @ tool
            f = base[:3, :3] @ w[:3]
            wc = np.concatenate([f, np.cross(tcp[:3, 3] - (fl[:3, :3] @ lp + fl[:3, 3]), f)])
            dev = stiff.compensate.truth_deviation(robot, truth, q[None], t_mp[None], wc[None])[0]
            r = dev[3:]
            out.append(np.linalg.norm(dev[:3] + np.cross(r, tcp[:3, 3] - t_mp[:3, 3])))
        return np.array(out)

    sim_nom, sim_opt = simulated(np.zeros(len(poses))), simulated(rot.psi)
    # the fit is noise-free: model and truth agree to far better than 1 %
    assert np.all(sim_opt <= sim_nom * 1.01)
    assert sim_opt.max() < sim_nom.max() and sim_opt.mean() < sim_nom.mean()


def test_configuration_change_is_an_error(robot, tmp_path):
    """A target 0.015 deg on the negative side of the wrist singularity: the compensation
    turns joint 5 positive, a wrist flip, which must not pass silently."""
    from stiff.olp.target import ArmGeometry, Configuration, JointMap

    # the paper's (soft) arm: the wrist turns by about 3e-4 rad under this load
    data = stiff.simulate(robot, stiff.random_design(robot, count=40, seed=3),
                          stiffness=[50914, 16382, 31311, 7791.1, 5613.6, 4000], tracker_sigma_m=0.0)
    m = stiff.Model(robot, stiff.identify(robot, data))
    q = np.array([0.3, 0.2, -0.4, 0.5, -2.5e-4, 0.2])
    c = Configuration.of(ArmGeometry(robot), q, JointMap())
    k = fr.pose_to_kuka(robot.tool_pose(q))
    p = tmp_path / "wrist.src"
    p.write_text("DEF wrist()\n$LOAD = LOAD_DATA[2]\nLIN {X %.6f, Y %.6f, Z %.6f, A %.6f, B %.6f, "
                 "C %.6f, S %d, T %d}\nEND\n" % (*k, c.kuka_status(), c.kuka_turn()))
    loads = {2: olp.ToolLoad(8.0, np.array([0.0, 0.0, 0.1]))}
    spec = olp.WrenchSpec(force=[100, 50, -200], tool_weight=True)
    with pytest.raises(olp.FilterError, match=r"wrist.src:3: .*changes the arm configuration "
                                              r"\(Status 110 -> Status 010\)"):
        olp.filter_program(olp.read_program(p, loads=loads), m, spec)
    with pytest.raises(olp.FilterError, match=r"LOAD_DATA\[2\].*--load 2"):
        olp.read_program(p)
    res = olp.filter_program(olp.read_program(p, loads=loads), m, spec,
                             olp.FilterOptions(allow_config_change=True))
    assert "configuration change" in res.targets[0].flags()
    assert "near-singular" in res.targets[0].flags()
    # the written Status is the compensated one
    assert re.search(r"S 2, T", res.texts["src"])
    # the tool weight of LOAD_DATA[2] is part of the wrench: 8 kg
    assert np.allclose(res.targets[0].wrench[:3], [100, 50, -200 - 8.0 * 9.80665])


def test_force_file_gives_the_wrench_per_target(model, programs, tmp_path):
    m, _ = model
    f = tmp_path / "forces.csv"
    f.write_text("# per-target process forces\ntarget,fx_N,fy_N,fz_N,mx_Nm,my_Nm,mz_Nm\n"
                 "3,10,20,-30,0,0,1\n5,0,0,-80,0,0,0\n")
    prog = olp.read_program(programs / "abb" / "Slot.mod")
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[0, 0, -50], force_file=str(f)))
    w = np.array([r.wrench for r in res.targets])
    assert np.allclose(w[2], [10, 20, -30, 0, 0, 1]) and np.allclose(w[4], [0, 0, -80, 0, 0, 0])
    assert np.allclose(w[3], [0, 0, -50, 0, 0, 0])   # constant force elsewhere on MoveL
    assert np.allclose(w[1], 0) and np.allclose(w[0], 0)  # MoveJ / MoveAbsJ: air
    f.write_text("target,fx_N,fy_N\n1,2,3\n")
    with pytest.raises(olp.FilterError, match="forces.csv:1: header"):
        olp.filter_program(prog, m, olp.WrenchSpec(force_file=str(f)))
    f.write_text("target,fx_N,fy_N,fz_N\n1,2,x,3\n")
    with pytest.raises(olp.FilterError, match="forces.csv:2:"):
        olp.filter_program(prog, m, olp.WrenchSpec(force_file=str(f)))


def test_damaged_programs_give_clear_errors(model, programs):
    """Truncated, cut or corrupted programs: a FilterError naming the file (or a clean
    result), never another exception; the input is never modified."""
    import random

    m, _ = model
    rng = random.Random(3)
    frames = dict(frames={1: fr.fanuc_to_pose(*WP)}, tools={1: fr.fanuc_to_pose(*TOOL)})
    files = [programs / "kuka" / "slot.src", programs / "kuka" / "slot.dat",
             programs / "abb" / "Slot.mod", programs / "fanuc" / "slot.ls",
             programs / "yaskawa" / "SLOT.JBI"]
    originals = {f: f.read_bytes() for f in files}
    for f in files:
        for _ in range(40):
            b = bytearray(originals[f])
            i = rng.randrange(len(b))
            op = rng.choice(["trunc", "flip", "del", "ins"])
            if op == "trunc":
                b = b[:i]
            elif op == "flip":
                b[i] = rng.choice(b"[]{},;:'\"0123456789.-eE XYZabc\n")
            elif op == "del":
                del b[i:i + rng.randrange(1, 20)]
            else:
                b[i:i] = bytes(rng.choice(b"[]{},;'-.9eE") for _ in range(rng.randrange(1, 4)))
            f.write_bytes(bytes(b))
            main = f.with_suffix(".src") if f.suffix == ".dat" else f
            try:
                prog = olp.read_program(main, **(frames if f.suffix in (".ls", ".JBI") else {}))
                olp.filter_program(prog, m, olp.WrenchSpec(force=[0, 0, -50], tool_weight=True))
            except olp.FilterError as e:
                assert main.name in str(e) or f.name in str(e), str(e)
            except stiff.StiffError:
                pass
            f.write_bytes(originals[f])


def test_configuration_flags_on_an_abb_arm(root):
    """IRB 120 (its robot file has ABB's joint zeros): at the zero pose the wrist centre is in
    front of axis 1 and of the lower arm; the flags follow the vendors' definitions."""
    from stiff.olp.target import ArmGeometry, Configuration, JointMap

    irb = stiff.Robot(str(root / "examples" / "robots" / "abb_irb120.yaml"))
    geo = ArmGeometry(irb)
    conf = lambda deg: Configuration.of(geo, np.radians(deg), JointMap())
    c = conf([0, 0, 0, 0, 30, 0])
    assert c.abb_confdata() == [0, 0, 0, 0] and c.kuka_status() == 2
    assert c.fanuc_config() == ("F", "U", "T", 0, 0, 0)
    assert conf([0, 0, 0, 0, -30, 0]).abb_confdata() == [0, 0, 0, 1]
    assert conf([-10, 0, 0, -100, 30, 200]).abb_confdata() == [-1, -2, 2, 0]
    assert conf([-10, 0, 0, -100, 30, 200]).fanuc_config()[3:] == (0, 0, 1)
    assert conf([0, 60, -100, 0, 30, 0]).abb_confdata()[3] == 2       # elbow down, in front
    assert conf([0, 0, -100, 0, 30, 0]).abb_confdata()[3] == 6        # forearm past vertical
    # behind axis 1: the arm leaning back over its base
    back = conf([0, -100, -60, 0, 30, 0])
    assert not back.front and back.abb_confdata()[3] >= 4 and back.kuka_status() & 1


def test_circular_moves_controller_frames_and_fanuc_joints(robot, model, tmp_path):
    """KRL CIRC (two inline targets) with BAS(#BASE/#TOOL, n) frames from the controller, and a
    Fanuc circular move (continuation line) plus a joint position: all compensated, FK check."""
    m, _ = model
    src = tmp_path / "circ.src"
    src.write_text("DEF circ()\n  BAS(#BASE, 1)\n  BAS(#TOOL, 2)\n"
                   "  LIN {X 60.0, Y 0.0, Z -2.0, A 0.0, B 10.0, C 180.0}\n"
                   "  CIRC {X 80.0, Y 30.0, Z -2.0, A 0.0, B 10.0, C 180.0}, "
                   "{X 60.0, Y 60.0, Z -2.0, A 0.0, B 10.0, C 180.0} C_DIS ; arc\nEND\n")
    frames = dict(frames={1: fr.kuka_to_pose(*WP)}, tools={2: fr.kuka_to_pose(*TOOL)})
    prog = olp.read_program(src, **frames)
    assert [t.motion for t in prog.targets] == ["LIN", "CIRC", "CIRC"]
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[0, 50, -100]))
    (tmp_path / "o").mkdir()
    res.write(tmp_path / "o")
    _check_program(robot, m, src, tmp_path / "o", res, **frames)
    # Fanuc: joint position P[1], linear P[2], circular via P[3] to P[4]
    q = np.radians([-8.0, -50.0, 8.0, -5.0, 52.0, -20.0])
    joint = "\t" + ",\t".join(f"J{i + 1}= {v:10.3f} deg" for i, v in enumerate(np.degrees(q)))
    pts = {2: (60, 0), 3: (80, 30), 4: (60, 60)}
    pos = ["P[1]{", "   GP1:", "\tUF : 1, UT : 1,", joint, "};"]
    for n, (x, y) in pts.items():
        pos += [f"P[{n}]{{", "   GP1:", "\tUF : 1, UT : 1,\t\tCONFIG : 'F U T, 0, 0, 0',",
                f"\tX = {x:9.3f}  mm,\tY = {y:9.3f}  mm,\tZ =    -2.000  mm,",
                "\tW =  180.000 deg,\tP =   10.000 deg,\tR =    0.000 deg", "};"]
    ls = tmp_path / "arc.ls"
    ls.write_text("\n".join(["/PROG  ARC", "/MN", "   1:J P[1] 20% FINE    ;",
                             "   2:L P[2] 20mm/sec FINE    ;", "   3:C P[3]    ;",
                             "    :  P[4] 20mm/sec CNT50    ;", "/POS"] + pos + ["/END", ""]))
    lsf = dict(frames={1: fr.fanuc_to_pose(*WP)}, tools={1: fr.fanuc_to_pose(*TOOL)})
    prog = olp.read_program(ls, **lsf)
    assert [(t.name, t.motion, t.joint) for t in prog.targets] == [
        ("P[1]", "J", True), ("P[2]", "L", False), ("P[3]", "C", False), ("P[4]", "C", False)]
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[0, 50, -100], tool_load=olp.ToolLoad(
        4.0, np.array([0, 0, 0.05])), tool_weight=True))
    (tmp_path / "o2").mkdir()
    res.write(tmp_path / "o2")
    _check_program(robot, m, ls, tmp_path / "o2", res, **lsf)


def test_tool_rotation_option_of_the_program_filter(model, programs, tmp_path):
    """--tool-rotation on the angled-head program: rotations within the limit and the step,
    deflection never above the programmed orientation's, the written orientation is the
    programmed one turned about the tool axis (up to the compensation's small rotation)."""
    m, _ = model
    src = programs / "abb" / "AngledHead.mod"
    prog = olp.read_program(src)
    opts = olp.FilterOptions(tool_rotation_limit_deg=60, tool_rotation_max_step_deg=10)
    res = olp.filter_program(prog, m, olp.WrenchSpec(force=[50, 60, -80], tool_weight=True), opts)
    psi = np.array([r.tool_rotation for r in res.targets])
    moves = [t.motion for t in prog.targets]
    assert np.all(np.abs(psi) <= math.radians(60) + 1e-12)
    assert all(p == 0 for p, mv in zip(psi, moves) if mv == "MoveJ")
    cut = [p for p, mv in zip(psi, moves) if mv == "MoveL"]
    assert np.all(np.abs(np.diff(cut)) <= math.radians(10) + 1e-9)
    for r in res.targets:
        assert np.linalg.norm(r.deflection[:3]) <= r.deflection_unrotated * (1 + 1e-12)
    (tmp_path / "o").mkdir()
    res.write(tmp_path / "o")
    again = olp.read_program(tmp_path / "o" / src.name)
    for t0, t1, r in zip(prog.targets, again.targets, res.targets):
        r0, r1 = _oracle_pose("ABB RAPID", t0.values)[:3, :3], _oracle_pose("ABB RAPID", t1.values)[:3, :3]
        rel = r0.T @ r1  # in the tool frame: a rotation about z by psi, plus < 1 mrad
        angle = math.atan2(rel[1, 0], rel[0, 0])
        assert abs(math.remainder(angle - r.tool_rotation, 2 * math.pi)) < 2e-3
        assert abs(rel[2, 2] - 1) < 1e-5
