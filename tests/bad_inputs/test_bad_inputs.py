"""Runs the bad-input catalogue (cases.py): each case must fail with its stated clear error, leave
every existing file as it was (inputs and an existing -o target) and leave no temporary file."""
from __future__ import annotations

import ctypes as C
import hashlib
import math
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from cases import CASES  # noqa: E402

import stiff  # noqa: E402
from stiff import _capi  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
ROBOT = ROOT / "examples" / "robots" / "rokae.yaml"
NAN, INF = math.nan, math.inf
SENTINEL = "existing output: a failing command must not touch this file\n"


def five_joint_urdf() -> str:
    joints, links = [], ["<link name='l0'/>"]
    for j in range(1, 6):
        links.append(f"<link name='l{j}'/>")
        axis = "0 0 1" if j % 2 else "0 1 0"
        joints.append(
            f"<joint name='j{j}' type='revolute'><parent link='l{j - 1}'/><child link='l{j}'/>"
            f"<origin xyz='0 0 0.2' rpy='0 0 0'/><axis xyz='{axis}'/>"
            "<limit lower='-3' upper='3' effort='10' velocity='1'/></joint>")
    return "<?xml version='1.0'?><robot name='five'>" + "".join(links + joints) + "</robot>\n"


def run_cli(*args, check=True):
    r = subprocess.run([sys.executable, "-m", "stiff.cli", *map(str, args)], capture_output=True,
                       text=True, timeout=300, stdin=subprocess.DEVNULL)
    if check and r.returncode != 0:
        raise RuntimeError(f"stiff {' '.join(map(str, args))}: {r.stderr}")
    return r


@pytest.fixture(scope="session")
def env(tmp_path_factory):
    """Good inputs shared by the cases (read only: their hashes are checked after each case)."""
    d = tmp_path_factory.mktemp("good")
    data, fit, design = d / "data.csv", d / "fit.json", d / "design.csv"
    run_cli("simulate", "--robot", "rokae", "--count", "12", "--seed", "3", "--stiffness",
            "50914,16382,31311,7791,5614,4000", "-o", data)
    run_cli("identify", "--robot", "rokae", "--data", data, "-o", fit)
    shutil.copy(ROOT / "examples" / "paper" / "design_kappa_a.csv", design)
    e = {"data": str(data), "fit": str(fit), "design": str(design), "robot": str(ROBOT),
         "root": str(ROOT), "dir": d}
    for v in (2, 3):
        p = d / f"arm{v}.fmu"
        r = run_cli("fmu", "export", "--robot", "rokae", "--fit", fit, "--fmi", v, "-o", p,
                    check=False)
        e[f"fmu{v}"] = str(p) if r.returncode == 0 else None
    return e


def snapshot(*dirs):
    out = {}
    for d in dirs:
        for p in pathlib.Path(d).rglob("*"):
            if p.is_file():
                out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def leftovers(*dirs):
    return [str(p) for d in dirs for p in pathlib.Path(d).rglob("*") if ".tmp" in p.name]


# ---------------------------------------------------------------- helpers of capi cases
class CApi:
    def __init__(self, env, tmp):
        self.env, self.tmp, self.keep = env, tmp, []
        self._robot = self._fit = None

    def out(self):
        h = C.c_void_p()
        self.keep.append(h)
        return C.byref(h)

    def dbl(self, values):
        a = (C.c_double * len(values))(*values)
        self.keep.append(a)
        return C.cast(a, _capi.c_double_p)

    def robot(self):
        if self._robot is None:
            self._robot = stiff.Robot(str(ROBOT))
        return self._robot._as_parameter_

    def dataset(self, displacement=True, zero_force=False, rows=12):
        ds = stiff.Dataset.read(self.env["data"])
        q, f, d = ds.q[:rows], ds.force[:rows], ds.displacement[:rows]
        if zero_force:
            f = f * 0.0
        n = len(q)
        h = C.c_void_p()
        st = _capi.lib.stiff_dataset_create(C.byref(h), n, 6, self.dbl(list(q.ravel())),
                                            self.dbl(list(f.ravel())), None,
                                            self.dbl(list(d.ravel())) if displacement else None,
                                            None)
        assert st == 0, _capi.last_error()
        self.keep.append(ds)
        return h

    def noise_options(self, struct_size):
        o = _capi.NoiseOptions()
        o.struct_size = struct_size
        self.keep.append(o)
        return C.byref(o)

    def options(self, struct_size_extra=0, poison=False, struct_size=None, **fields):
        o = _capi.IdentifyOptions()
        o.struct_size = C.sizeof(o) + struct_size_extra if struct_size is None else struct_size
        for k, v in fields.items():
            setattr(o, k, v)
        buf = C.create_string_buffer(C.sizeof(o) + struct_size_extra)
        C.memmove(buf, C.byref(o), C.sizeof(o))
        if poison:
            buf[C.sizeof(o)] = b"\x01"
        self.keep.extend([o, buf])
        return C.cast(buf, C.POINTER(_capi.IdentifyOptions))

    def fit(self):
        f = stiff.Fit.read(self.env["fit"])
        self.keep.append(f)
        return f._as_parameter_

    def model(self):
        m = stiff.Model(stiff.Robot(str(ROBOT)), stiff.Fit.read(self.env["fit"]))
        self.keep.append(m)
        return m._as_parameter_

    def namespace(self):
        return {"lib": _capi.lib, "out": self.out, "dbl": self.dbl, "robot": self.robot,
                "dataset": self.dataset, "options": self.options, "model": self.model,
                "noise_options": self.noise_options,
                "fit": self.fit,
                "NAN": NAN, "INF": INF}


# ---------------------------------------------------------------- helpers of FMU cases
class Fmu:
    """fmpy driving: each helper returns (an FMI call failed, the FMU's error log)."""

    def __init__(self, tmp):
        self.tmp = tmp
        self.fmpy = pytest.importorskip("fmpy")

    def _instance(self, path, guid=None, edit=None):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        md = read_model_description(path)
        unzip = extract(path, str(self.tmp / "unzipped"))
        if edit == "delete-model":
            for p in pathlib.Path(unzip, "resources").glob("model*"):
                p.unlink()
        v3 = md.fmiVersion.startswith("3")
        log = []
        self._last_log = log
        cls = FMU3Slave if v3 else FMU2Slave
        fmu = cls(guid=guid or md.guid, unzipDirectory=unzip,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bad")
        vr = {v.name: v.valueReference for v in md.modelVariables}
        if v3:
            def logger(env, status, category, message):
                log.append((status, message.decode()))
            fmu.instantiate(loggingOn=False, logMessage=logger)
        else:
            from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

            def logger(env, name, status, category, message):
                log.append((status, message.decode()))
            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(logger)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(self.fmpy.calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(self.fmpy.free)
            try:
                from fmpy.logging import addLoggerProxy
                addLoggerProxy(C.byref(cb))
            except Exception:
                pass
            self._keep = (logger, cb)
            fmu.instantiate(loggingOn=False, callbacks=cb)
        return fmu, vr, v3, log

    @staticmethod
    def _errors(log):
        return [m for s, m in log if s >= 3]

    def _start(self, fmu, v3):
        if v3:
            fmu.enterInitializationMode(startTime=0.0)
        else:
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
        fmu.exitInitializationMode()

    def fmu_set(self, path, started=False, **values):
        fmu, vr, v3, log = self._instance(path)
        if started:
            self._start(fmu, v3)
        failed = False
        try:
            refs, vals = [vr[k] for k in values], [float(v) for v in values.values()]
            fmu.setFloat64(refs, vals) if v3 else fmu.setReal(refs, vals)
        except Exception:
            failed = True
        fmu.freeInstance()
        return failed, self._errors(log)

    def fmu_set_int(self, path, **values):
        fmu, vr, v3, log = self._instance(path)
        failed = False
        try:
            refs, vals = [vr[k] for k in values], [int(v) for v in values.values()]
            fmu.setInt32(refs, vals) if v3 else fmu.setInteger(refs, vals)
        except Exception:
            failed = True
        fmu.freeInstance()
        return failed, self._errors(log)

    def fmu_instantiate(self, path, guid=None, edit=None):
        log = []
        try:
            fmu, _, _, log = self._instance(path, guid=guid, edit=edit)
        except Exception as e:  # fmpy raises when instantiate returns NULL
            errors = [str(e)]
            inst_log = getattr(self, "_last_log", [])
            return True, errors + self._errors(inst_log)
        fmu.freeInstance()
        return False, self._errors(log)

    def namespace(self):
        return {"fmu_set": self.fmu_set, "fmu_set_int": self.fmu_set_int,
                "fmu_instantiate": self.fmu_instantiate, "NAN": NAN, "INF": INF}


def fit_edit(path, tmp, edit):
    """A copy of the fit file at `path` changed by edit(json) (a bad fit for a case)."""
    import json

    j = json.loads(pathlib.Path(path).read_text())
    edit(j)
    out = pathlib.Path(tmp) / "edited_fit.json"
    out.write_text(json.dumps(j))
    return str(out)


def swap(lst, a, b):
    lst[a], lst[b] = lst[b], lst[a]


def put(obj, key, value):
    obj[key] = value


# ---------------------------------------------------------------- the runner
def fill(text: str, subs: dict) -> str:
    for k, v in subs.items():
        text = text.replace("{" + k + "}", str(v))
    return text.replace("{{", "{").replace("}}", "}")


@pytest.mark.parametrize("case", CASES, ids=[c["id"] for c in CASES])
def test_bad_input(case, env, tmp_path):
    subs = {k: v for k, v in env.items() if isinstance(v, str)}
    subs["tmp"] = str(tmp_path)
    if case["kind"] == "fmu":
        for v in (2, 3):
            subs[f"fmu{v}"] = env[f"fmu{v}"] or ""
    for name, text in case.get("files", {}).items():
        text = text.replace("@FIVE_JOINT_URDF@", five_joint_urdf())
        text = text.replace("@ROKAE@", ROBOT.read_text())
        (tmp_path / name).write_text(fill(text, subs) if "{tmp}" in text else text)
    out = tmp_path / "existing_output.keep"
    out.write_text(SENTINEL)
    subs["out"] = str(out)
    before = snapshot(tmp_path, env["dir"])
    message = fill(case["message"], subs)

    if case["kind"] == "cli":
        r = run_cli(*[fill(a, subs) for a in case["args"]], check=False)
        assert r.returncode == case.get("exit", 2), (r.returncode, r.stdout, r.stderr)
        assert "Traceback" not in r.stderr, r.stderr
        if case.get("one_line", True):
            assert len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert message in r.stderr, r.stderr
    elif case["kind"] == "capi":
        api = CApi(env, tmp_path)
        status = eval(fill(case["code"], subs), api.namespace())
        err = _capi.last_error()
        assert status == case["status"], (status, err)
        assert message in err, err
    elif case["kind"] == "python":
        with pytest.raises(Exception) as e:
            eval(fill(case["code"], subs), {"stiff": stiff, "np": np, "NAN": NAN, "INF": INF,
                                            "fit_edit": fit_edit, "swap": swap, "put": put})
        names = [k.__name__ for k in type(e.value).__mro__]
        assert case["error"] in names, (type(e.value), e.value)
        if "status" in case:
            assert getattr(e.value, "status", None) == case["status"], e.value
        assert message in str(e.value), str(e.value)
        assert "Traceback" not in str(e.value)
    elif case["kind"] == "fmu":
        if not subs.get("fmu2"):
            pytest.skip("FMU binaries not built")
        failed, errors = eval(fill(case["code"], subs), Fmu(tmp_path).namespace())
        assert failed, "the FMU accepted the bad input"
        assert any(message in m for m in errors), errors
    else:
        raise AssertionError(f"unknown kind {case['kind']}")

    after = snapshot(tmp_path, env["dir"])
    changed = [p for p in before if before[p] != after.get(p)]
    assert not changed, f"files modified or removed by a failing call: {changed}"
    assert out.read_text() == SENTINEL
    assert not leftovers(tmp_path, env["dir"]), leftovers(tmp_path, env["dir"])


def test_catalogue_is_large_and_unique():
    ids = [c["id"] for c in CASES]
    assert len(ids) == len(set(ids))
    assert len(CASES) >= 40
    assert {c["kind"] for c in CASES} == {"cli", "capi", "python", "fmu"}
