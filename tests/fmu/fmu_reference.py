"""Helpers of the FMU tests (tests/fmu, bench/fmu_bench.py): FMUs of the ROKAE arm exported through the C ABI (ctypes on
libstiff_c.so) with the joint stiffness of the paper, and an independent numpy reference of
the joint-compliance model d = J C J^T W."""

import ctypes
import json
import os
import pathlib

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
BUILD = pathlib.Path(os.environ.get("STIFF_BUILD_DIR", ROOT / "build"))
ROBOT = ROOT / "examples" / "robots" / "rokae.yaml"
# Joint stiffness of Jiang & Fang (2023) [N*m/rad].
STIFFNESS = np.array([50914.0, 16382.0, 31311.0, 7791.1, 5613.6, 4000.0])

# Modified DH table of examples/robots/rokae.yaml (alpha [deg], a [mm], d [mm]), written out
# again here so that the reference does not share code with the library.
DH = [(0, 0, 0), (-90, 30, 0), (0, 340, 0), (-90, 35, 345), (90, 0, 0), (-90, 0, 87)]


class FmuOptions(ctypes.Structure):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("fmi_version", ctypes.c_uint32),
        ("model_identifier", ctypes.c_char_p),
        ("binaries_dir", ctypes.c_char_p),
        ("array_inputs", ctypes.c_uint32),
    ]


def load_capi():
    path = BUILD / "capi" / "libstiff_c.so"
    if not path.exists():
        pytest.skip(f"{path} not built (set STIFF_BUILD_DIR)")
    lib = ctypes.CDLL(str(path))
    lib.stiff_last_error.restype = ctypes.c_char_p
    lib.stiff_robot_load.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_char_p]
    lib.stiff_result_read_json.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_char_p]
    lib.stiff_fmu_export.argtypes = [
        ctypes.c_char_p,
        ctypes.c_void_p,
        ctypes.c_void_p,
        ctypes.POINTER(FmuOptions),
    ]
    lib.stiff_robot_destroy.argtypes = [ctypes.c_void_p]
    lib.stiff_result_destroy.argtypes = [ctypes.c_void_p]
    return lib


def fit_json(compliance, robot_name="rokae", robot_file=ROBOT):
    params = [
        {"effect": "joint", "name": f"c{j + 1}", "unit": "rad/(N*m)", "value": float(c)}
        for j, c in enumerate(compliance)
    ]
    return {
        "format": "stiff-fit",
        "version": 1,
        "robot": {"name": robot_name, "file": str(robot_file)},
        "model": ["joint"],
        "method": "linear_least_squares",
        "parameters": params,
    }


class Exporter:
    """Writes FMUs through stiff_fmu_export."""

    def __init__(self, tmp):
        self.lib = load_capi()
        self.tmp = tmp
        self.robot = ctypes.c_void_p()
        if self.lib.stiff_robot_load(ctypes.byref(self.robot), str(ROBOT).encode()) != 0:
            raise RuntimeError(self.lib.stiff_last_error().decode())

    def load_robot(self, path):
        """Handle of another robot file (freed with the process)."""
        robot = ctypes.c_void_p()
        if self.lib.stiff_robot_load(ctypes.byref(robot), str(path).encode()) != 0:
            raise RuntimeError(self.lib.stiff_last_error().decode())
        name = ctypes.create_string_buffer(256)
        self.lib.stiff_robot_name.argtypes = [ctypes.c_char_p, ctypes.c_size_t,
                                              ctypes.POINTER(ctypes.c_size_t), ctypes.c_void_p]
        assert self.lib.stiff_robot_name(name, len(name), None, robot) == 0
        dof = ctypes.c_size_t()
        self.lib.stiff_robot_dof.argtypes = [ctypes.POINTER(ctypes.c_size_t), ctypes.c_void_p]
        assert self.lib.stiff_robot_dof(ctypes.byref(dof), robot) == 0
        return robot, name.value.decode(), dof.value

    def export(self, name, fmi_version=2, compliance=None, model_identifier=None,
               robot_file=None, array_inputs=0):
        robot, robot_name = self.robot, "rokae"
        if robot_file is not None:
            robot, robot_name, dof = self.load_robot(robot_file)
            compliance = np.full(dof, 5e-5) if compliance is None else compliance
        compliance = 1.0 / STIFFNESS if compliance is None else compliance
        fit_path = self.tmp / (name + ".fit.json")
        fit_path.write_text(json.dumps(fit_json(compliance, robot_name, robot_file or ROBOT)))
        fit = ctypes.c_void_p()
        if self.lib.stiff_result_read_json(ctypes.byref(fit), str(fit_path).encode()) != 0:
            raise RuntimeError(self.lib.stiff_last_error().decode())
        opts = FmuOptions(ctypes.sizeof(FmuOptions), fmi_version, model_identifier, None,
                          array_inputs)
        out = self.tmp / (name + ".fmu")
        status = self.lib.stiff_fmu_export(str(out).encode(), robot, fit, ctypes.byref(opts))
        self.lib.stiff_result_destroy(fit)
        if robot is not self.robot:
            self.lib.stiff_robot_destroy(robot)
        if status != 0:
            raise RuntimeError(self.lib.stiff_last_error().decode())
        return str(out)


# ---------------------------------------------------------------- independent reference
def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _trans(x, y, z):
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def forward(q):
    """Axes, origins and the flange pose of the ROKAE arm (modified DH, Craig)."""
    t = np.eye(4)
    axes, origins = [], []
    for (alpha, a, d), qi in zip(DH, q):
        t = t @ _rot_x(np.radians(alpha)) @ _trans(a / 1000.0, 0, 0) @ _rot_z(qi)
        t = t @ _trans(0, 0, d / 1000.0)
        axes.append(t[:3, 2].copy())
        origins.append(t[:3, 3].copy())
    return np.array(axes), np.array(origins), t


def jacobian(q):
    axes, origins, flange = forward(q)
    p = flange[:3, 3]
    jac = np.zeros((6, len(q)))
    for j in range(len(q)):
        jac[:3, j] = np.cross(axes[j], p - origins[j])
        jac[3:, j] = axes[j]
    return jac, flange


def reference(q, wrench, compliance=None, tool_frame=False):
    """(dx, dy, dz, rx, ry, rz) = J C J^T W at the flange (measured = load point)."""
    compliance = 1.0 / STIFFNESS if compliance is None else np.asarray(compliance)
    jac, flange = jacobian(np.asarray(q, float))
    w = np.asarray(wrench, float)
    if tool_frame:
        r = flange[:3, :3]
        w = np.concatenate([r @ w[:3], r @ w[3:]])
    return jac @ (compliance * (jac.T @ w))


def tool_position(q):
    return forward(np.asarray(q, float))[2][:3, 3]


def rodrigues(w):
    a = np.linalg.norm(w)
    if a == 0:
        return np.eye(3)
    k = w / a
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * kx @ kx
