"""FMU of the compliant-arm deflection model, tested with fmpy against an independent
numpy reference (docs/fmu.md)."""

import ctypes
import json
import pathlib
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmu_reference import STIFFNESS, reference, rodrigues, tool_position, forward

fmpy = pytest.importorskip("fmpy")
from fmpy import extract, read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (  # noqa: E402
    FMU2Model,
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.fmi3 import FMU3Model, FMU3Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

TOL = 1e-12
Q = [0.3, -0.4, 0.5, 0.2, 0.9, -0.3]  # a pose away from singularities [rad]
W = [300.0, -200.0, 150.0, 10.0, -5.0, 8.0]  # (F [N], M [N*m])
WRENCH = ["fx", "fy", "fz", "mx", "my", "mz"]
DEFL = ["dx", "dy", "dz", "rx", "ry", "rz"]
ROBOTS = sorted(p for p in (pathlib.Path(__file__).resolve().parents[2] / "examples" / "robots")
                .iterdir() if p.suffix in (".yaml", ".urdf"))


# ---------------------------------------------------------------- helpers
class Log:
    """Captures the FMU's log messages (FMI 2 and FMI 3 signatures)."""

    def __init__(self):
        self.messages = []  # (status, category, message)

    def fmi2(self):
        def logger(env, name, status, category, message):
            self.messages.append((status, category.decode(), message.decode()))

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(ctypes.byref(cb))
        except Exception:  # pragma: no cover - fmpy without the proxy
            pass
        self._keep = (logger, cb)
        return cb

    def fmi3(self, env, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    def errors(self):
        return [m for s, c, m in self.messages if s == 3]


class Instance:
    """One fmpy instance with name-based access."""

    def __init__(self, path, kind="cs", name="arm", unzipdir=None, log=None, guid=None,
                 logging_on=False):
        self.md = read_model_description(path)
        self.unzipdir = unzipdir or extract(path)
        self.v3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.log = log or Log()
        ident = (self.md.coSimulation if kind == "cs" else self.md.modelExchange).modelIdentifier
        cls = {(False, "cs"): FMU2Slave, (False, "me"): FMU2Model,
               (True, "cs"): FMU3Slave, (True, "me"): FMU3Model}[(self.v3, kind)]
        self.fmu = cls(guid=guid or self.md.guid, unzipDirectory=self.unzipdir,
                       modelIdentifier=ident, instanceName=name)
        if self.v3:
            self.fmu.instantiate(loggingOn=logging_on, logMessage=self.log.fmi3)
        else:
            self.fmu.instantiate(loggingOn=logging_on, callbacks=self.log.fmi2())
        self.kind = kind
        self.time = 0.0

    def init(self):
        if self.v3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()

    def exit_init(self):
        self.fmu.exitInitializationMode()
        if self.kind == "me" and not self.v3:
            self.fmu.newDiscreteStates()
            self.fmu.enterContinuousTimeMode()
        elif self.kind == "me":
            self.fmu.updateDiscreteStates()
            self.fmu.enterContinuousTimeMode()

    def start(self):
        self.init()
        self.exit_init()
        return self

    def set(self, **values):
        vrs = [self.vr[k] for k in values]
        vals = [float(v) for v in values.values()]
        if self.v3:
            self.fmu.setFloat64(vrs, vals)
        else:
            self.fmu.setReal(vrs, vals)

    def set_inputs(self, q, w):
        self.set(**{f"q{j + 1}": x for j, x in enumerate(q)}, **dict(zip(WRENCH, w)))

    def get(self, names):
        vrs = [self.vr[n] for n in names]
        return np.array(self.fmu.getFloat64(vrs) if self.v3 else self.fmu.getReal(vrs))

    def deflection(self):
        return self.get(DEFL)

    def qcmd(self):
        return self.get([f"q_cmd{j + 1}" for j in range(6)])

    def step(self, h=0.01):
        self.fmu.doStep(self.time, h)
        self.time += h

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


@pytest.fixture(params=[2, 3], ids=["fmi2", "fmi3"])
def fmu(request, fmu2, fmu3):
    return fmu2 if request.param == 2 else fmu3


# ---------------------------------------------------------------- 1, 2: static checks
def test_validate_fmu_is_clean(fmu):
    assert validate_fmu(fmu) == []
    cli = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", fmu],
                         capture_output=True, text=True)
    assert cli.returncode == 0, cli.stdout + cli.stderr


def test_static_structure(fmu):
    md = read_model_description(fmu)
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
        root = ET.fromstring(z.read("modelDescription.xml"))
        model_txt = z.read("resources/model.txt").decode()
    assert "modelDescription.xml" in names
    assert all("\\" not in n and not n.startswith("./") and not n.startswith("/") for n in names)
    platform = "linux64" if md.fmiVersion == "2.0" else "x86_64-linux"
    assert f"binaries/{platform}/stiff_arm.so" in names
    assert {"resources/model.txt", "resources/robot.yaml", "documentation/index.html"} <= set(names)
    assert any("BSD-2" in n for n in names) and any("MPL-2.0" in n for n in names)
    # Inputs carry a start value and no `initial`.
    for el in root.iter():
        if el.get("causality") == "input":
            assert el.get("initial") is None
    guid = md.guid
    assert re.search(r"^guid " + re.escape(guid) + "$", model_txt, re.M)
    names_ = {v.name for v in md.modelVariables}
    assert {f"joint_c{j}" for j in range(1, 7)} <= names_
    assert {"x_tool", "y_tool", "z_tool", "wrench_frame"} <= names_
    c1 = next(v for v in md.modelVariables if v.name == "joint_c1")
    assert c1.causality == "parameter" and c1.variability == "tunable"
    assert float(c1.start) == pytest.approx(1 / STIFFNESS[0], rel=1e-15)
    assert c1.unit == "rad/(N.m)" and float(c1.min) == 0.0
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    assert len(md.outputs) == len(outputs) == 6 + 3 + 6
    # One set of inputs: the scalars (arrays only when asked for, test_fmi3_array_inputs).
    assert not [v.name for v in md.modelVariables if v.dimensions]
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    assert inputs == [f"q{j}" for j in range(1, 7)] + WRENCH


# ---------------------------------------------------------------- 3: binary hygiene
def test_binary_hygiene(fmu, tmp_path):
    with zipfile.ZipFile(fmu) as z:
        so = [n for n in z.namelist() if n.endswith(".so")][0]
        z.extract(so, tmp_path)
    lib = str(tmp_path / so)
    dyn = subprocess.run(["readelf", "-d", lib], capture_output=True, text=True).stdout
    needed = set(re.findall(r"\(NEEDED\).*\[(.*)\]", dyn))
    # libgcc_s (the unwinder) is on every Linux; libstdc++ is linked in.
    assert needed <= {"libc.so.6", "libm.so.6", "ld-linux-x86-64.so.2", "libgcc_s.so.1"}, needed
    syms = subprocess.run(["nm", "-D", "--defined-only", lib], capture_output=True,
                          text=True).stdout.split("\n")
    names = [line.split()[-1] for line in syms if line.strip()]
    assert names and all(n.startswith(("fmi2", "fmi3")) for n in names), names
    # The glibc floor of docs/fmu.md: no symbol version newer than GLIBC_2.17 (RHEL 7, Debian 8,
    # Ubuntu 14.04 and later); it was 2.36 (arc4random, _dl_find_object, hypot, stat, ...).
    dynsyms = subprocess.run(["objdump", "-T", lib], capture_output=True, text=True).stdout
    versions = re.findall(r"GLIBC_(\d+)\.(\d+)", dynsyms)
    assert versions and max((int(a), int(b)) for a, b in versions) <= (2, 17), \
        [line for line in dynsyms.splitlines() if re.search(r"GLIBC_2\.(1[89]|[2-9]\d)", line)]
    gcc = re.findall(r"GCC_(\d+)\.(\d+)", dynsyms)  # libgcc_s symbols: GCC 4.2 has them all
    assert max((int(a), int(b)) for a, b in gcc) <= (4, 2)


# ---------------------------------------------------------------- 4: simulation vs reference
def piecewise_input(fmu):
    md = read_model_description(fmu)
    names = [f"q{j + 1}" for j in range(6)] + WRENCH
    steps = [  # (time, q, wrench): held from `time` on
        (0.0, Q, W),
        (0.25, [0.1, 0.2, -0.3, 0.4, -0.8, 0.5], [-100.0, 250.0, 80.0, -3.0, 4.0, 0.0]),
        (0.55, [-0.5, 0.3, 0.2, -0.6, 1.1, 2.0], [0.0, 0.0, -400.0, 0.0, 12.0, -6.0]),
    ]
    rows = []
    for k, (t, q, w) in enumerate(steps):
        if k > 0:  # repeat the time with the new value: a step in fmpy's input table
            rows.append((t, *steps[k - 1][1], *steps[k - 1][2]))
        rows.append((t, *q, *w))
    rows.append((1.0, *steps[-1][1], *steps[-1][2]))
    dtype = [("time", np.float64)] + [(n, np.float64) for n in names]
    assert md is not None
    return np.array(rows, dtype=dtype), steps


def held(steps, t):
    cur = steps[0]
    for s in steps:
        if t >= s[0] - 1e-12:
            cur = s
    return cur


@pytest.mark.parametrize("kind,solver", [("CoSimulation", None), ("ModelExchange", "Euler"),
                                         ("ModelExchange", "CVode")])
def test_simulation_matches_reference(fmu, kind, solver):
    signal, steps = piecewise_input(fmu)
    outs = DEFL + ["x_tool", "y_tool", "z_tool"] + [f"q{j + 1}" for j in range(6)] + WRENCH
    kw = {"solver": solver} if solver else {}
    res = simulate_fmu(fmu, fmi_type=kind, start_time=0, stop_time=1.0, output_interval=0.1,
                       input=signal, output=outs, record_events=False, **kw)
    assert len(res) >= 10
    for k, row in enumerate(res):
        t = row["time"]
        q = np.array([row[f"q{j + 1}"] for j in range(6)])
        w = np.array([row[n] for n in WRENCH])
        # CS: the outputs at t were computed with the input applied at the previous sample.
        tin = t if kind == "ModelExchange" or k == 0 else res[k - 1]["time"]
        _, hq, hw = held(steps, tin)
        # (fmpy interpolates the table linearly: equal ends may differ in the last bit)
        np.testing.assert_allclose(q, hq, atol=1e-15, rtol=0)
        np.testing.assert_allclose(w, hw, atol=1e-12, rtol=0)
        d = np.array([row[n] for n in DEFL])
        np.testing.assert_allclose(d, reference(q, w), rtol=0, atol=TOL)
        p = np.array([row["x_tool"], row["y_tool"], row["z_tool"]])
        np.testing.assert_allclose(p, tool_position(q) + d[:3], rtol=0, atol=TOL)


# ---------------------------------------------------------------- 5: physics
def test_zero_linear_and_stiffness_scaling(fmu):
    a = Instance(fmu).start()
    a.set_inputs(Q, [0] * 6)
    assert np.all(a.deflection() == 0.0)
    assert np.all(a.qcmd() == np.array(Q))
    a.set_inputs(Q, W)
    d1 = a.deflection()
    a.set_inputs(Q, 2 * np.array(W))
    np.testing.assert_allclose(a.deflection(), 2 * d1, rtol=1e-14, atol=1e-18)
    a.set(**{f"joint_c{j + 1}": 0.5 / STIFFNESS[j] for j in range(6)})  # k x 2
    np.testing.assert_allclose(a.deflection(), d1, rtol=1e-14, atol=1e-18)
    a.free()


def test_wrench_in_tool_frame(fmu):
    a = Instance(fmu)
    if a.v3:
        a.fmu.setInt32([a.vr["wrench_frame"]], [1])
    else:
        a.fmu.setInteger([a.vr["wrench_frame"]], [1])
    a.start()
    a.set_inputs(Q, W)
    np.testing.assert_allclose(a.deflection(), reference(Q, W, tool_frame=True), atol=TOL, rtol=0)
    a.free()


def test_compensation_puts_loaded_tool_on_target(fmu):
    a = Instance(fmu).start()
    a.set_inputs(Q, W)
    qc = a.qcmd()
    d = reference(qc, W)
    _, _, f0 = forward(np.array(Q))
    _, _, fc = forward(qc)
    np.testing.assert_allclose(fc[:3, 3] + d[:3], f0[:3, 3], rtol=0, atol=TOL)
    np.testing.assert_allclose(rodrigues(d[3:]) @ fc[:3, :3], f0[:3, :3], rtol=0, atol=TOL)
    assert np.max(np.abs(qc - Q)) > 1e-5  # it did move
    a.free()


@pytest.fixture(scope="session")
def fmu3_arrays(exporter):
    return exporter.export("arm3_arrays", 3, array_inputs=1)


def test_fmi3_array_inputs(fmu3_arrays):
    """With array inputs the FMU has q[6] and wrench[6] and no scalar inputs: a master that
    writes every input writes each value once (the arrays used to share storage with the
    scalars, and fmpy warned "missing input" for the arrays on every run fed scalars)."""
    assert validate_fmu(fmu3_arrays) == []
    md = read_model_description(fmu3_arrays)
    inputs = {v.name: v for v in md.modelVariables if v.causality == "input"}
    assert set(inputs) == {"q", "wrench"}
    assert [int(d.start) for d in inputs["q"].dimensions] == [6]
    assert (inputs["q"].valueReference, inputs["wrench"].valueReference) == (110, 111)
    a = Instance(fmu3_arrays).start()
    # The start values are the home pose, element by element.
    start = [float(x) for x in inputs["q"].start.split()]
    np.testing.assert_array_equal(a.fmu.getFloat64([110], nValues=6), start)
    a.fmu.setFloat64([a.vr["q"], a.vr["wrench"]], Q + W)
    np.testing.assert_array_equal(a.fmu.getFloat64([a.vr["q"]], nValues=6), Q)
    np.testing.assert_allclose(a.deflection(), reference(Q, W), atol=TOL, rtol=0)
    with pytest.raises(FMICallException):
        a.fmu.setFloat64([a.vr["q"]], Q[:5])  # nValues does not match
    with pytest.raises(FMICallException):
        a.fmu.setFloat64([1], [0.1])  # no scalar q1 in this FMU
    a.fmu.freeInstance()


@pytest.mark.parametrize("arrays", [False, True], ids=["scalars", "arrays"])
def test_fmi3_simulation_feeds_every_input(fmu3, fmu3_arrays, arrays, capsys):
    """fmpy fed a table with the FMU's inputs: no "missing input" warning, and the values flow
    into the outputs."""
    path = fmu3_arrays if arrays else fmu3
    if arrays:
        dtype = [("time", np.float64), ("q", np.float64, (6,)), ("wrench", np.float64, (6,))]
        signal = np.array([(0.0, Q, W), (1.0, Q, W)], dtype=dtype)
    else:
        dtype = [("time", np.float64)] + [(f"q{j + 1}", np.float64) for j in range(6)] + \
            [(n, np.float64) for n in WRENCH]
        signal = np.array([(0.0, *Q, *W), (1.0, *Q, *W)], dtype=dtype)
    res = simulate_fmu(path, start_time=0, stop_time=0.2, output_interval=0.1, input=signal,
                       output=DEFL)
    out = capsys.readouterr()
    assert "missing input" not in (out.out + out.err).lower()
    np.testing.assert_allclose([res[-1][n] for n in DEFL], reference(Q, W), atol=TOL, rtol=0)


# ---------------------------------------------------------------- 6: start values
def test_start_values(fmu):
    base = dict(start_time=0, stop_time=0.1, output_interval=0.05, output=DEFL)
    sv = {"q1": 0.3, "q2": -0.4, "q5": 0.9, "fx": 100.0, "mz": 3.0}
    r1 = simulate_fmu(fmu, start_values=sv, apply_default_start_values=True, **base)
    r2 = simulate_fmu(fmu, start_values=sv, apply_default_start_values=False, **base)
    assert np.array_equal(r1.view(np.float64), r2.view(np.float64))
    # Joints not given keep the start values of the model description (the home pose).
    md = {v.name: v for v in read_model_description(fmu).modelVariables}
    q = [sv.get(f"q{j + 1}", float(md[f"q{j + 1}"].start)) for j in range(6)]
    np.testing.assert_allclose([r1[0][n] for n in DEFL], reference(q, [100, 0, 0, 0, 0, 3]),
                               atol=TOL, rtol=0)
    r3 = simulate_fmu(fmu, start_values={**sv, "joint_c2": 2 / STIFFNESS[1]}, **base)
    c = 1 / STIFFNESS
    c[1] *= 2
    np.testing.assert_allclose([r3[0][n] for n in DEFL], reference(q, [100, 0, 0, 0, 0, 3], c),
                               atol=TOL, rtol=0)
    with pytest.raises(Exception):
        simulate_fmu(fmu, start_values={"no_such_variable": 1.0}, **base)


def test_values_in_initialization_mode(fmu):
    a = Instance(fmu)
    a.init()
    assert a.get(["joint_c3"])[0] == 1 / STIFFNESS[2]
    a.set_inputs(Q, W)
    np.testing.assert_allclose(a.deflection(), reference(Q, W), atol=TOL, rtol=0)
    a.exit_init()
    a.free()


# ---------------------------------------------------------------- 7: bad parameters
@pytest.mark.parametrize("bad", [-1e-5, float("nan"), float("inf")])
def test_bad_parameter_is_rejected_and_resettable(fmu, bad):
    a = Instance(fmu)
    with pytest.raises(FMICallException) as e:
        a.set(joint_c2=bad)
    assert e.value.status == 3
    assert any("joint_c2" in m for m in a.log.errors()), a.log.messages
    a.fmu.reset()
    a.set(joint_c2=2e-5)
    a.start()
    a.set_inputs(Q, W)
    c = 1 / STIFFNESS
    c[1] = 2e-5
    np.testing.assert_allclose(a.deflection(), reference(Q, W, c), atol=TOL, rtol=0)
    a.free()


def test_bad_input_and_wrench_frame(fmu):
    a = Instance(fmu).start()
    with pytest.raises(FMICallException):
        a.set(q1=float("nan"))
    assert a.log.errors()
    a.fmu.reset()
    with pytest.raises(FMICallException):
        if a.v3:
            a.fmu.setInt32([a.vr["wrench_frame"]], [7])
        else:
            a.fmu.setInteger([a.vr["wrench_frame"]], [7])
    a.fmu.freeInstance()


def _corrupt(fmu, tmp_path, edit):
    d = tmp_path / "x"
    shutil.rmtree(d, ignore_errors=True)
    extract(fmu, str(d))
    p = d / "resources" / "model.txt"
    edit(p)
    return str(d)


@pytest.mark.parametrize("edit", [
    lambda p: p.unlink(),
    lambda p: p.write_text(p.read_text().replace("variables", "variablez")),
    lambda p: p.write_text(p.read_text().replace("effects 1 joint", "effects 1 no_such_effect")),
], ids=["missing", "malformed", "unknown_effect"])
def test_missing_or_malformed_model_file(fmu, tmp_path, edit):
    d = _corrupt(fmu, tmp_path, edit)
    log = Log()
    with pytest.raises(Exception):
        Instance(fmu, unzipdir=d, log=log)
    assert log.errors(), "instantiate must say why"


# ---------------------------------------------------------------- 8: instantiate arguments
def test_wrong_guid_and_empty_name(fmu):
    log = Log()
    with pytest.raises(Exception):
        Instance(fmu, guid="{00000000-0000-0000-0000-000000000000}", log=log)
    assert any("does not match" in m for m in log.errors())
    with pytest.raises(Exception):
        Instance(fmu, name="")


# ---------------------------------------------------------------- 9: call sequence
def test_call_sequence_violations(fmu):
    a = Instance(fmu)
    with pytest.raises(FMICallException):
        a.fmu.doStep(0.0, 0.1)  # before initialization
    with pytest.raises(FMICallException):
        a.deflection()  # getReal in Instantiated
    a.start()
    with pytest.raises(FMICallException):
        a.fmu.doStep(0.0, 0.0)  # h <= 0
    with pytest.raises(FMICallException):
        a.fmu.doStep(0.5, 0.1)  # wrong t
    with pytest.raises(FMICallException):
        a.fmu.exitInitializationMode()
    a.step()
    a.free()


# ---------------------------------------------------------------- 10: instances
def test_two_instances_are_independent(fmu):
    unzip = extract(fmu)
    a = Instance(fmu, name="a", unzipdir=unzip)
    b = Instance(fmu, name="b", unzipdir=unzip)
    b.set(**{f"joint_c{j + 1}": 3 / STIFFNESS[j] for j in range(6)})
    a.start()
    b.start()
    for k in range(5):
        a.set_inputs(Q, np.array(W) * (k + 1))
        b.set_inputs(Q, W)
        a.step()
        b.step()
        np.testing.assert_allclose(a.deflection(), reference(Q, np.array(W) * (k + 1)), atol=TOL,
                                   rtol=0)
        np.testing.assert_allclose(b.deflection(), reference(Q, W, 3 / STIFFNESS), atol=TOL,
                                   rtol=0)
    a.free()
    b.free()


# ---------------------------------------------------------------- 11: FMU state
STATE_SCRIPT = r"""
import sys, numpy as np
sys.path.insert(0, {here!r})
from test_fmu import Instance, DEFL
a = Instance({fmu!r}).start()
a.fmu.doStep(0.0, 0.01)
a.time = 0.01
st = a.fmu.deSerializeFMUstate(open({blob!r}, 'rb').read()) if not a.v3 else \
     a.fmu.deserializeFMUState(open({blob!r}, 'rb').read())
(a.fmu.setFMUState if a.v3 else a.fmu.setFMUstate)(st)
print(' '.join(repr(float(x)) for x in a.get(DEFL + ['q_cmd1', 'joint_c1'])))
"""


def test_fmu_state_roundtrip(fmu, tmp_path):
    a = Instance(fmu).start()
    get_state = a.fmu.getFMUState if a.v3 else a.fmu.getFMUstate
    set_state = a.fmu.setFMUState if a.v3 else a.fmu.setFMUstate
    free_state = a.fmu.freeFMUState if a.v3 else a.fmu.freeFMUstate
    ser = a.fmu.serializeFMUState if a.v3 else a.fmu.serializeFMUstate
    deser = a.fmu.deserializeFMUState if a.v3 else a.fmu.deSerializeFMUstate
    a.set_inputs(Q, W)
    a.set(joint_c1=3e-5)
    a.step()
    names = DEFL + ["q_cmd1", "joint_c1"]
    before = a.get(names)
    s = get_state()
    blob = ser(s)
    a.set_inputs([0.0] * 6, [1, 2, 3, 0, 0, 0])
    a.set(joint_c1=1e-6)
    a.step()
    assert not np.array_equal(a.get(names), before)
    set_state(s)
    assert np.array_equal(a.get(names), before)
    s2 = deser(blob)
    a.set_inputs([0.0] * 6, [1, 2, 3, 0, 0, 0])
    set_state(s2)
    assert np.array_equal(a.get(names), before)
    for bad in (blob[:-9], b"XXXX" + blob[4:], blob + b"\0"):
        with pytest.raises(FMICallException):
            deser(bad)
    free_state(s)
    free_state(s2)
    # A fresh process restores the same outputs bit for bit.
    (tmp_path / "state.bin").write_bytes(blob)
    script = STATE_SCRIPT.format(here=str(pathlib.Path(__file__).parent), fmu=fmu,
                                 blob=str(tmp_path / "state.bin"))
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         cwd=str(tmp_path))
    assert out.returncode == 0, out.stderr
    assert np.array_equal(np.array([float(x) for x in out.stdout.split()]), before)
    a.free()


# ---------------------------------------------------------------- 12: lifecycle
def test_reset_reproduces_first_run(fmu):
    a = Instance(fmu)

    def run():
        a.time = 0.0
        a.start()
        out = []
        for k in range(4):
            a.set_inputs(np.array(Q) * (1 + 0.1 * k), W)
            a.step()
            out.append(np.concatenate([a.deflection(), a.qcmd()]))
        return np.array(out)

    first = run()
    a.fmu.terminate()
    a.fmu.reset()
    assert np.array_equal(run(), first)
    a.free()


def test_simulate_reuses_instance_for_a_sweep(fmu2):
    md = read_model_description(fmu2)
    unzip = extract(fmu2)
    inst = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
                     modelIdentifier=md.coSimulation.modelIdentifier, instanceName="sweep")
    inst.instantiate()
    sv = {f"q{j + 1}": Q[j] for j in range(6)}
    sv["fz"] = -500.0
    for scale in (1.0, 2.0, 4.0):
        r = simulate_fmu(unzip, model_description=md, fmu_instance=inst, stop_time=0.02,
                         output_interval=0.01, output=["dz"],
                         start_values={**sv, "joint_c2": scale / STIFFNESS[1]})
        c = 1 / STIFFNESS
        c[1] *= scale
        assert r[-1]["dz"] == pytest.approx(reference(Q, [0, 0, -500, 0, 0, 0], c)[2], abs=TOL)
        inst.reset()
    inst.freeInstance()


# ---------------------------------------------------------------- 13: resources and URIs
def test_resources_under_odd_path(fmu, tmp_path):
    d = tmp_path / "with space %41 ü"
    extract(fmu, str(d))
    a = Instance(fmu, unzipdir=str(d)).start()
    a.set_inputs(Q, W)
    np.testing.assert_allclose(a.deflection(), reference(Q, W), atol=TOL, rtol=0)
    a.free()


def test_fmi2_uri_forms(fmu2, tmp_path):
    d = tmp_path / "uri 100%"
    extract(fmu2, str(d))
    md = read_model_description(fmu2)
    res = (d / "resources").resolve()
    quoted = pathlib.Path(res).as_uri()  # file:///...%20...%25
    forms = [quoted, quoted.replace("file:///", "file:/"),
             quoted.replace("file:///", "file://localhost/")]
    for uri in forms:
        f = FMU2Slave(guid=md.guid, unzipDirectory=str(d), modelIdentifier="stiff_arm",
                      instanceName="u")
        log = Log()
        f.callbacks = log.fmi2()
        comp = f.fmi2Instantiate(b"u", 1, md.guid.encode(), uri.encode(),
                                 ctypes.byref(f.callbacks), 0, 0)
        assert comp, (uri, log.messages)
        f.component = comp
        f.freeInstance()


# ---------------------------------------------------------------- 14: logging
def test_only_declared_log_categories(fmu):
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    declared = {c.get("name") for c in root.iter("Category")}
    a = Instance(fmu, logging_on=True).start()
    a.set_inputs(Q, W)
    a.deflection()
    with pytest.raises(FMICallException):
        a.set(joint_c1=-1.0)
    a.fmu.freeInstance()
    cats = {c for _, c, _ in a.log.messages}
    assert cats and cats <= declared
    assert any(s == 0 for s, _, _ in a.log.messages)  # logCalls when on
    b = Instance(fmu, logging_on=False).start()
    b.set_inputs(Q, W)
    b.deflection()
    b.free()
    assert not [m for m in b.log.messages if m[0] == 0]


# ---------------------------------------------------------------- 16: long run
def test_long_run_many_instances(fmu2):
    unzip = extract(fmu2)
    insts = [Instance(fmu2, name=f"i{k}", unzipdir=unzip).start() for k in range(4)]
    for k in range(2000):
        for i, a in enumerate(insts):
            a.set_inputs(Q, np.array(W) * (i + 1))
            a.step(1e-3)
    for i, a in enumerate(insts):
        np.testing.assert_allclose(a.deflection(), reference(Q, np.array(W) * (i + 1)), atol=TOL,
                                   rtol=0)
        a.free()


# ---------------------------------------------------------------- export errors (C ABI)
def test_export_errors(exporter, tmp_path):
    with pytest.raises(RuntimeError, match="fmi_version"):
        exporter.export("bad_version", fmi_version=4)
    with pytest.raises(RuntimeError, match="identifier"):
        exporter.export("bad_id", model_identifier=b"1 bad")
    with pytest.raises(RuntimeError, match="outside"):
        exporter.export("bad_c", compliance=-1 / STIFFNESS)
    with pytest.raises(RuntimeError, match="array inputs need FMI 3"):
        exporter.export("bad_arrays", fmi_version=2, array_inputs=1)
    with pytest.raises(RuntimeError, match="array_inputs must be 0"):
        exporter.export("bad_arrays3", fmi_version=3, array_inputs=2)
    assert not list(exporter.tmp.glob("bad_*.fmu"))  # nothing written


# ---------------------------------------------------------------- value references
def _effects_fit(exporter, effects):
    """A fit of the ROKAE arm with `effects`, every parameter at 0.3 of its typical value."""
    lib = exporter.lib
    lib.stiff_effect_describe.argtypes = [ctypes.c_char_p, ctypes.c_size_t,
                                          ctypes.POINTER(ctypes.c_size_t), ctypes.c_void_p,
                                          ctypes.c_char_p]
    buf = ctypes.create_string_buffer(1 << 16)
    params = []
    for name in effects:
        assert lib.stiff_effect_describe(buf, len(buf), None, exporter.robot, name.encode()) == 0
        for p in json.loads(buf.value.decode())["parameters"]:
            lo, hi = float(p["lower"]), float(p["upper"])
            params.append({"effect": name, "name": p["name"],
                           "value": float(np.clip(0.3 * float(p["typical"]), lo, hi))})
    return {"format": "stiff-fit", "version": 1, "robot": {"name": "rokae"},
            "model": list(effects), "parameters": params}


def _export_fit(exporter, fit, out, version):
    from fmu_reference import FmuOptions

    lib = exporter.lib
    fit_path = out.with_suffix(".fit.json")
    fit_path.write_text(json.dumps(fit))
    res = ctypes.c_void_p()
    assert lib.stiff_result_read_json(ctypes.byref(res), str(fit_path).encode()) == 0, \
        lib.stiff_last_error()
    opts = FmuOptions(ctypes.sizeof(FmuOptions), version, None, None)
    status = lib.stiff_fmu_export(str(out).encode(), exporter.robot, res, ctypes.byref(opts))
    lib.stiff_result_destroy(res)
    assert status == 0, lib.stiff_last_error()
    return str(out)


@pytest.mark.parametrize("version", [2, 3])
def test_fixed_variables_keep_their_value_references(exporter, tmp_path, version):
    """A master that stores connections by value reference survives a re-export with another
    model: dx was 19 in a joint FMU and 25 in joint + point_offset. The map of docs/fmu.md."""
    fmus = [_export_fit(exporter, _effects_fit(exporter, effects), tmp_path / f"m{i}.fmu", version)
            for i, effects in enumerate((["joint"], ["joint", "point_offset"], ["point_offset"]))]
    fmus.append(exporter.export(f"ur10_{version}", version,
                                robot_file=ROBOTS[[p.stem for p in ROBOTS].index("ur10")]))
    refs = []
    for path in fmus:
        md = read_model_description(path)
        refs.append({v.name: v.valueReference for v in md.modelVariables})
    fixed = {f"q{j}": j for j in range(1, 7)}
    fixed.update({n: 100 + k for k, n in enumerate(WRENCH)})
    fixed.update({"wrench_frame": 120})
    fixed.update({n: 200 + k for k, n in enumerate(DEFL)})
    fixed.update({n: 210 + k for k, n in enumerate(["x_tool", "y_tool", "z_tool"])})
    fixed.update({f"q_cmd{j}": 300 + j for j in range(1, 7)})
    if version == 3:
        fixed["time"] = 0
    arrays = {"q": 110, "wrench": 111}  # FMI 3 with array inputs
    for r in refs:
        assert {n: r[n] for n in fixed} == fixed
        assert all(r[n] == x for n, x in arrays.items() if n in r)
        params = {n: x for n, x in r.items() if n not in fixed and n not in arrays}
        assert params and min(params.values()) >= 1000  # the model's parameters, after the range
    # The model's parameters differ; each is numbered from 1000 in model order.
    assert refs[1]["joint_c1"] == 1000 and refs[1]["point_offset_" + next(
        n.split("point_offset_")[1] for n in refs[2] if n.startswith("point_offset_"))] == 1006
    # And the FMUs work through those references.
    for path in fmus[:3]:
        a = Instance(path).start()
        a.set_inputs(Q, W)
        assert np.all(np.isfinite(a.deflection())) and np.all(np.isfinite(a.qcmd()))
        a.free()
        assert a.log.errors() == []


# ---------------------------------------------------------------- every effect vs the C ABI
def test_all_effects_match_c_abi(exporter, tmp_path):
    """The FMU evaluates whatever effects the fit names with the library's own code: compare a
    fit with every effect that needs no data against stiff_predict of the C ABI."""
    lib = exporter.lib
    lib.stiff_effect_count.restype = ctypes.c_size_t
    lib.stiff_effect_name.argtypes = [ctypes.c_char_p, ctypes.c_size_t,
                                      ctypes.POINTER(ctypes.c_size_t), ctypes.c_size_t]
    lib.stiff_effect_describe.argtypes = [ctypes.c_char_p, ctypes.c_size_t,
                                          ctypes.POINTER(ctypes.c_size_t), ctypes.c_void_p,
                                          ctypes.c_char_p]
    buf = ctypes.create_string_buffer(1 << 16)
    model, params = [], []
    for i in range(lib.stiff_effect_count()):
        assert lib.stiff_effect_name(buf, len(buf), None, i) == 0
        name = buf.value.decode()
        assert lib.stiff_effect_describe(buf, len(buf), None, exporter.robot, name.encode()) == 0
        desc = json.loads(buf.value.decode())
        if any(n in ("time", "sessions") for n in desc.get("needs", [])):
            continue
        model.append(name)
        for p in desc["parameters"]:
            lo, hi = float(p["lower"]), float(p["upper"])
            v = float(np.clip(0.3 * float(p["typical"]), lo, hi))
            params.append({"effect": name, "name": p["name"], "value": v})
    fit = {"format": "stiff-fit", "version": 1, "robot": {"name": "rokae"}, "model": model,
           "parameters": params}
    fit_path = tmp_path / "all.fit.json"
    fit_path.write_text(json.dumps(fit))
    res = ctypes.c_void_p()
    assert lib.stiff_result_read_json(ctypes.byref(res), str(fit_path).encode()) == 0, \
        lib.stiff_last_error()
    m = ctypes.c_void_p()
    lib.stiff_model_create.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_void_p,
                                       ctypes.c_void_p]
    assert lib.stiff_model_create(ctypes.byref(m), exporter.robot, res) == 0, lib.stiff_last_error()
    lib.stiff_predict.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_void_p,
                                  ctypes.POINTER(ctypes.c_double), ctypes.c_size_t,
                                  ctypes.POINTER(ctypes.c_double)]
    for v in (2, 3):
        out = tmp_path / f"all{v}.fmu"
        from fmu_reference import FmuOptions

        opts = FmuOptions(ctypes.sizeof(FmuOptions), v, None, None)
        assert lib.stiff_fmu_export(str(out).encode(), exporter.robot, res,
                                    ctypes.byref(opts)) == 0, lib.stiff_last_error()
        assert validate_fmu(str(out)) == []
        a = Instance(str(out)).start()
        rng = np.random.default_rng(7)
        for _ in range(5):
            q = rng.uniform(-1, 1, 6)
            w = rng.uniform(-300, 300, 6)
            a.set_inputs(q, w)
            d = (ctypes.c_double * 6)()
            assert lib.stiff_predict(d, m, (ctypes.c_double * 6)(*q), 6,
                                     (ctypes.c_double * 6)(*w)) == 0
            np.testing.assert_allclose(a.deflection(), np.array(d[:]), rtol=0, atol=TOL)
        a.free()
    lib.stiff_result_destroy(res)
    assert len(model) > 1, model


# ---------------------------------------------------------------- 16: valgrind
@pytest.mark.skipif(shutil.which("valgrind") is None or shutil.which("cc") is None,
                    reason="valgrind or cc missing")
def test_valgrind_clean(fmu2, tmp_path):
    """Instantiate, 500 deflection + 50 compensation evaluations, free: no leak, no error."""
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "bench"))
    import fmu_bench

    md = read_model_description(fmu2)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    macros = {
        "IN_VR": [vr[f"q{j + 1}"] for j in range(6)] + [vr[n] for n in WRENCH],
        "OUT_VR": [vr[n] for n in DEFL],
        "CMD_VR": [vr[f"q_cmd{j + 1}"] for j in range(6)],
    }
    exe = tmp_path / "drive"
    subprocess.run(["cc", "-O1", "-g", "-std=c99", "-D_POSIX_C_SOURCE=200809L",
                    f"-I{fmu_bench.fmi_headers()}"]
                   + [f"-D{k}={','.join(map(str, v))}" for k, v in macros.items()]
                   + [str(pathlib.Path(fmu_bench.__file__).with_suffix(".c")), "-o", str(exe),
                      "-ldl"], check=True)
    r = subprocess.run(["valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite",
                        "--error-exitcode=9", str(exe), extract(fmu2), md.guid, "500"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]


def test_compensation_warning_is_logged_once_per_evaluation(fmu):
    """At the all-zero pose (a wrist singularity) a load makes compensation fail to converge:
    one warning per evaluation, not one per q_cmd output read (fmusim showed 6 per read)."""
    a = Instance(fmu).start()
    a.set_inputs([0.0] * 6, [200.0, -150.0, 300.0, 0.0, 0.0, 0.0])
    try:
        a.qcmd()
    except Exception:  # fmpy raises on a Warning only in strict modes
        pass
    try:
        a.qcmd()  # the same evaluation read again: nothing new to say
    except Exception:
        pass
    warnings = [m for s, _, m in a.log.messages if s == 1]
    a.free()
    assert len(warnings) == 1, warnings


def _state_calls(a):
    if a.v3:
        return (a.fmu.getFMUState, a.fmu.setFMUState, a.fmu.freeFMUState,
                a.fmu.serializeFMUState, a.fmu.deserializeFMUState)
    return (a.fmu.getFMUstate, a.fmu.setFMUstate, a.fmu.freeFMUstate, a.fmu.serializeFMUstate,
            a.fmu.deSerializeFMUstate)


def test_fmu_state_sizes_are_told_for_the_whole_blob(fmu):
    a = Instance(fmu).start()
    get_state, _, free_state, ser, deser = _state_calls(a)
    s = get_state()
    blob = ser(s)
    for bad, said in ((blob[:-1], f"has {len(blob) - 1} bytes, expected {len(blob)} (truncated?)"),
                      (blob + b"\0", f"has {len(blob) + 1} bytes, expected {len(blob)} (extra")):
        with pytest.raises(FMICallException):
            deser(bad)
        assert any(said in m for m in a.log.errors()), (said, a.log.errors())
    free_state(s)
    a.free()


def test_fmu_state_freed_twice_is_an_error_not_a_crash(fmu):
    """fmusim frees a state twice; the second call must be an Error."""
    a = Instance(fmu).start()
    get_state, set_state, free_state, ser, _ = _state_calls(a)
    s = get_state()
    stale = ctypes.c_void_p(s.value)
    free_state(s)
    for call in (lambda: free_state(stale), lambda: set_state(stale), lambda: ser(stale)):
        with pytest.raises(FMICallException):
            call()
    assert any("not an FMU state of this instance" in m for m in a.log.errors())
    a.free()


def test_co_simulation_state_is_refused_by_model_exchange(fmu):
    cs = Instance(fmu, kind="cs").start()
    get_cs, _, free_cs, ser_cs, _ = _state_calls(cs)
    s = get_cs()
    blob = ser_cs(s)
    me = Instance(fmu, kind="me").start()
    _, _, _, _, deser_me = _state_calls(me)
    with pytest.raises(FMICallException):
        deser_me(blob)
    assert any("state of the other interface" in m for m in me.log.errors()), me.log.errors()
    free_cs(s)
    cs.free()
    me.free()


def test_fmi3_event_mode_is_refused_when_the_fmu_has_none(fmu3):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(fmu3)
    log = Log()
    f = FMU3Slave(guid=md.guid, unzipDirectory=extract(fmu3),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="ev")
    with pytest.raises(Exception):
        f.instantiate(eventModeUsed=True, logMessage=log.fmi3)
    assert any("fmi3InstantiateCoSimulation: eventModeUsed = true" in m
               for m in log.errors()), log.messages


def test_absurd_wrench_is_reported_as_overflow(fmu):
    """1e308 N gave a deflection of 1e303 m with status OK and q_cmd == q 'singular pose'."""
    a = Instance(fmu).start()
    a.set_inputs(Q, [1e308, 0, 0, 0, 0, 0])
    with pytest.raises(FMICallException):
        a.deflection()
    assert any("the deflection overflows" in m for m in a.log.errors()), a.log.messages
    a.fmu.freeInstance()


# ---------------------------------------------------------------- start pose


@pytest.mark.parametrize("robot", ROBOTS, ids=[p.stem for p in ROBOTS])
@pytest.mark.parametrize("version", [2, 3])
def test_start_pose_is_not_singular(exporter, robot, version):
    """Evaluated at its start values under a load, every output is OK and finite: the joint
    inputs start at a home pose away from singularities (the all-zero pose is a wrist
    singularity of most arms, where the compensation cannot converge: fmusim stopped at t = 0
    on the Warning). The start attributes are the instance's initial values."""
    path = exporter.export(f"home_{robot.stem}_{version}", version, robot_file=robot)
    md = read_model_description(path)
    qs = sorted((v for v in md.modelVariables if re.fullmatch(r"q\d+", v.name)),
                key=lambda v: int(v.name[1:]))
    start = np.array([float(v.start) for v in qs])
    a = Instance(path).start()
    np.testing.assert_array_equal(a.get([v.name for v in qs]), start)
    a.set(fx=200.0, fy=-150.0, fz=300.0, mx=5.0, my=-5.0, mz=3.0)
    out = a.get(DEFL + ["x_tool", "y_tool", "z_tool"] + [f"q_cmd{j + 1}" for j in range(len(qs))])
    assert np.all(np.isfinite(out))
    assert np.linalg.norm(out[:3]) > 1e-5  # the load deflects the arm ...
    assert np.max(np.abs(out[9:] - start)) > 1e-6  # ... and the compensation moves the joints
    a.free()
    assert [m for s, _, m in a.log.messages if s != 0] == []


def test_most_joints_a_robot_may_have_works_everywhere(exporter, tmp_path):
    """64 joints (stiff::kMaxJoints) load, make a data set and an FMU that runs; 65 are refused
    by the robot reader (before, the reader took 65 and stiff_dataset_create refused them)."""
    lib = exporter.lib
    row = "  - {alpha: 90, a: 0.05, d: 0.01, limits: [-170, 170]}\n"
    head = "name: snake{n}\nconvention: modified_dh\nunits: {{length: m, angle: deg}}\njoints:\n"
    for n in (64, 65):
        (tmp_path / f"snake{n}.yaml").write_text(head.format(n=n) + row * n)
    with pytest.raises(RuntimeError, match="the robot has 65 joints; at most 64"):
        exporter.load_robot(tmp_path / "snake65.yaml")
    robot, _, dof = exporter.load_robot(tmp_path / "snake64.yaml")
    assert dof == 64
    ds = ctypes.c_void_p()
    lib.stiff_dataset_create.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_size_t,
                                         ctypes.c_size_t] + [ctypes.c_void_p] * 5
    assert lib.stiff_dataset_create(ctypes.byref(ds), 1, 64, (ctypes.c_double * 64)(),
                                    (ctypes.c_double * 3)(), None, None, None) == 0
    lib.stiff_dataset_destroy.argtypes = [ctypes.c_void_p]
    lib.stiff_dataset_destroy(ds)
    assert lib.stiff_dataset_create(ctypes.byref(ds), 1, 65, (ctypes.c_double * 65)(),
                                    (ctypes.c_double * 3)(), None, None, None) != 0
    assert b"1..64" in lib.stiff_last_error()
    lib.stiff_robot_destroy(robot)
    path = exporter.export("snake64", 3, robot_file=tmp_path / "snake64.yaml",
                           compliance=np.full(64, 1e-6))
    a = Instance(path).start()
    a.set(fx=10.0, fy=-5.0, fz=20.0)
    out = a.get(DEFL + [f"q_cmd{j}" for j in range(1, 65)])
    assert np.all(np.isfinite(out)) and a.vr["q_cmd64"] == 364 and a.vr["q64"] == 64
    a.free()
    assert a.log.errors() == []
