"""Inverse kinematics, machining paths and deflection compensation (docs/compensation.md).

numpy in, numpy out; every loop over points runs in C (one call per path). SI units (m, rad,
N, N*m), base frame. Poses are 4 x 4 homogeneous transforms of the tool (measured point with
the flange orientation); arrays of poses are (N, 4, 4)."""
from __future__ import annotations

import ctypes as C
import math
import os
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from . import _capi as _c
from . import _outputs
from ._capi import check, lib
from .api import Model, Robot

__all__ = ["ToolPath", "read_path", "inverse_kinematics", "ik_is_analytic", "tool_poses",
           "compensate_pose", "compensate_path", "Compensation", "truth_deviation",
           "pose_from_xyz_rpy", "xyz_rpy_from_pose", "quaternion_from_pose", "rotation_angle_between", "status_text", "plot_deviation",
           "POINT_SINGULAR", "POINT_UNREACHABLE", "POINT_BRANCH_CHANGE", "POINT_JUMP",
           "POINT_NOT_CONVERGED"]

POINT_SINGULAR = 1
POINT_UNREACHABLE = 2
POINT_BRANCH_CHANGE = 4
POINT_JUMP = 8
POINT_NOT_CONVERGED = 16
_STATUS_NAMES = [(POINT_SINGULAR, "singular"), (POINT_UNREACHABLE, "unreachable"),
                 (POINT_BRANCH_CHANGE, "branch change (wrist flip)"), (POINT_JUMP, "joint jump"),
                 (POINT_NOT_CONVERGED, "compensation not converged")]


def status_text(code: int) -> str:
    """'ok' or the problems of a point status, e.g. 'singular, joint jump'."""
    names = [n for bit, n in _STATUS_NAMES if int(code) & bit]
    return ", ".join(names) if names else "ok"


def pose_from_xyz_rpy(xyz_rpy) -> np.ndarray:
    """4 x 4 pose from (x, y, z [m], rx, ry, rz [rad]), fixed-axis XYZ: R = Rz Ry Rx."""
    x, y, z, rx, ry, rz = map(float, xyz_rpy)
    cx, sx, cy, sy, cz, sz = (math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry),
                              math.cos(rz), math.sin(rz))
    t = np.eye(4)
    t[:3, :3] = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ \
        np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ \
        np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    t[:3, 3] = (x, y, z)
    return t


def quaternion_from_pose(poses: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (qw, qx, qy, qz), qw >= 0, of (N, 4, 4) poses: no gimbal lock,
    unlike roll-pitch-yaw (Shepperd's method: the largest of the four terms first)."""
    r = np.asarray(poses, dtype=float).reshape(-1, 4, 4)[:, :3, :3]
    out = np.empty((r.shape[0], 4))
    for i, m in enumerate(r):
        tr = m[0, 0] + m[1, 1] + m[2, 2]
        k = int(np.argmax([tr, m[0, 0], m[1, 1], m[2, 2]]))
        if k == 0:
            s = 2 * math.sqrt(1 + tr)
            q = [s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif k == 1:
            s = 2 * math.sqrt(1 + m[0, 0] - m[1, 1] - m[2, 2])
            q = [(m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif k == 2:
            s = 2 * math.sqrt(1 + m[1, 1] - m[0, 0] - m[2, 2])
            q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s]
        else:
            s = 2 * math.sqrt(1 + m[2, 2] - m[0, 0] - m[1, 1])
            q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4]
        q = np.array(q)
        out[i] = (q if q[0] >= 0 else -q) / np.linalg.norm(q)
    return out


def rotation_angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) angle [rad] of the rotation from the orientations of poses a to those of b."""
    ra = np.asarray(a, dtype=float).reshape(-1, 4, 4)[:, :3, :3]
    rb = np.asarray(b, dtype=float).reshape(-1, 4, 4)[:, :3, :3]
    rel = np.einsum("nji,njk->nik", ra, rb)  # Ra^T Rb
    # atan2 of |vee(R - R^T)| / 2 and (tr R - 1) / 2: accurate for small and large angles.
    s = 0.5 * np.linalg.norm(np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                                       rel[:, 1, 0] - rel[:, 0, 1]], axis=1), axis=1)
    c = 0.5 * (np.trace(rel, axis1=1, axis2=2) - 1)
    return np.arctan2(s, c)


def rotation_from_vector(w: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of (N, 3) rotation vectors [rad] (Rodrigues)."""
    w = np.asarray(w, dtype=float).reshape(-1, 3)
    t = np.linalg.norm(w, axis=1)
    k = np.zeros((len(w), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    k -= np.transpose(k, (0, 2, 1))
    small = t < 1e-8
    s = np.where(small, 1.0 - t ** 2 / 6, np.sin(t) / np.where(small, 1.0, t))
    c = np.where(small, 0.5 - t ** 2 / 24, (1 - np.cos(t)) / np.where(small, 1.0, t) ** 2)
    return np.eye(3) + s[:, None, None] * k + c[:, None, None] * (k @ k)


def rotation_vector_angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) angle [rad] of the rotation between orientations given as rotation vectors."""
    pa, pb = np.tile(np.eye(4), (len(a), 1, 1)), np.tile(np.eye(4), (len(b), 1, 1))
    pa[:, :3, :3], pb[:, :3, :3] = rotation_from_vector(a), rotation_from_vector(b)
    return rotation_angle_between(pa, pb)


def xyz_rpy_from_pose(poses: np.ndarray) -> np.ndarray:
    """(N, 6) (x, y, z [m], rx, ry, rz [rad]) of (N, 4, 4) poses (inverse of pose_from_xyz_rpy)."""
    p = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
    r = p[:, :3, :3]
    ry = np.arctan2(-r[:, 2, 0], np.hypot(r[:, 0, 0], r[:, 1, 0]))
    rx = np.arctan2(r[:, 2, 1], r[:, 2, 2])
    rz = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    return np.column_stack([p[:, :3, 3], rx, ry, rz])


@dataclass
class ToolPath:
    """A path read from a CSV or G-code file, base frame, SI."""

    poses: np.ndarray             # (N, 4, 4)
    wrench: Optional[np.ndarray]  # (N, 6) per-point (F, M) at the load point, or None
    lines: np.ndarray             # (N,) source line of every point
    source: str
    rapid: Optional[np.ndarray] = None  # (N,) bool: G0 (positioning) moves, no process force

    def __len__(self) -> int:
        return self.poses.shape[0]


def path_defaults() -> dict:
    """The library's path-reading defaults (stiff_path_options_init): frame (x, y, z [m],
    rx, ry, rz [rad]), the default tool orientation tool_rpy [rad] and segment_m [m]."""
    o = _c.defaults(_c.PathOptions)
    return {"frame": list(o.frame), "tool_rpy": list(o.tool_rpy), "segment_m": o.segment_m}


def read_path(path, frame: Optional[Sequence[float]] = None,
              tool_rpy: Optional[Sequence[float]] = None,
              segment_m: Optional[float] = None) -> ToolPath:
    """Read a path: .csv (tool poses, optional wrench columns) or G-code (any other extension);
    a file or a built-in path by name ("rokae_contour", "pocket.nc").
    `frame`: workpiece frame in the base frame (x, y, z [m], rx, ry, rz [rad]); `tool_rpy`:
    tool orientation in the workpiece frame [rad] for G-code and CSV without orientation
    (default: pointing down); `segment_m`: split G1 moves into pieces of at most this length
    (default: end points only). Unset arguments keep the library's defaults
    (stiff_path_options_init). Raises ParseError with path, line and column."""
    from .data import find

    path = find("paths", path)
    o = _c.defaults(_c.PathOptions)
    if frame is not None:
        o.frame[:] = [float(v) for v in frame]
    if tool_rpy is not None:
        o.tool_rpy[:] = [float(v) for v in tool_rpy]
        o.flags |= _c.PATH_TOOL_RPY
    if segment_m is not None:
        o.segment_m = float(segment_m)
    _outputs.note_input(path)
    name = _c.encode(os.fspath(path))
    rows, has_w = C.c_size_t(0), C.c_int(0)
    st = lib.stiff_path_read(None, None, None, 0, C.byref(rows), C.byref(has_w), name, C.byref(o))
    if st not in (0, -5):
        check(st)
    n = rows.value
    poses, wrench = np.empty((n, 4, 4)), np.empty((n, 6))
    lines = np.empty(n, dtype=np.uint32)
    check(lib.stiff_path_read(_c.ptr(poses), _c.ptr(wrench),
                              lines.ctypes.data_as(C.POINTER(C.c_uint32)), n, C.byref(rows),
                              C.byref(has_w), name, C.byref(o)))
    flags = np.zeros(n, dtype=np.uint32)
    check(lib.stiff_path_read_flags(flags.ctypes.data_as(C.POINTER(C.c_uint32)), n,
                                    C.byref(rows), name, C.byref(o)))
    return ToolPath(poses, wrench if has_w.value else None, lines.astype(np.int64),
                    os.fspath(path), (flags & _c.PATH_POINT_RAPID) != 0)


def ik_is_analytic(robot: Robot) -> bool:
    """True if the robot's IK is analytic (6R with spherical wrist, axes 2 and 3 parallel)."""
    a = C.c_int()
    check(lib.stiff_ik_analytic(C.byref(a), robot))
    return bool(a.value)


def _poses(poses) -> np.ndarray:
    p = np.ascontiguousarray(poses, dtype=np.float64)
    if p.shape[-2:] != (4, 4):
        raise ValueError(f"poses must be 4 x 4 transforms, got shape {p.shape}")
    return p.reshape(-1, 4, 4)


def tool_poses(robot: Robot, q) -> np.ndarray:
    """(N, 4, 4) tool poses at joint rows q (N x n, or one row n) [rad]: e.g. FK(q_cmd)."""
    return robot.tool_pose(np.atleast_2d(np.asarray(q, dtype=np.float64)))


def inverse_kinematics(robot: Robot, pose, q_seed=None, *, path: Optional[bool] = None):
    """Inverse kinematics of the tool pose.

    One 4 x 4 pose: every solution within the joint limits, (k, n) [rad], nearest q_seed first
    (analytic robots: up to 8; StiffError NumericalError when unreachable).
    (N, 4, 4) poses (or path=True): the joint path with the branch kept, returned as
    (q (N, n), status (N,)) where status holds POINT_* bits (unreachable points hold the
    previous q; see status_text)."""
    p = _poses(pose)
    as_path = path if path is not None else np.ndim(pose) == 3
    n = robot.dof
    seed = None if q_seed is None else _c.as_array(q_seed)
    if seed is not None and seed.size != n:
        raise ValueError(f"q_seed has {seed.size} values for a {n}-joint robot")
    if not as_path:
        return _c.get_doubles(lib.stiff_ik, robot, _c.ptr(p), None if seed is None else
                              _c.ptr(seed)).reshape(-1, n)
    rows = p.shape[0]
    q = np.empty((rows, n))
    status = np.zeros(rows, dtype=np.intc)
    needed = C.c_size_t()
    check(lib.stiff_ik_path(_c.ptr(q), q.size, C.byref(needed),
                            status.ctypes.data_as(_c.c_int_p), robot, _c.ptr(p), rows,
                            None if seed is None else _c.ptr(seed)))
    return q, status.astype(np.int64)


def _wrench_rows(wrench, rows: int) -> np.ndarray:
    w = np.atleast_2d(np.asarray(wrench, dtype=np.float64))
    if w.shape[1] == 3:
        w = np.hstack([w, np.zeros((w.shape[0], 3))])
    if w.shape[1] != 6:
        raise ValueError(f"wrench must have 3 or 6 columns, has {w.shape[1]}")
    if w.shape[0] == 1 and rows != 1:
        w = np.repeat(w, rows, axis=0)
    if w.shape[0] != rows:
        raise ValueError(f"wrench has {w.shape[0]} rows for {rows} poses")
    return np.ascontiguousarray(w)


def compensate_pose(model: Model, q, wrench) -> np.ndarray:
    """Joint command q_cmd [rad] such that the loaded tool reaches FK(q) under the wrench
    (F [N], M [N*m] at the load point, base frame; a 3-vector is a pure force)."""
    qa = _c.as_array(q)
    w = _wrench_rows(wrench, 1)[0].copy()
    out = np.empty(qa.size)
    check(lib.stiff_compensate_pose(_c.ptr(out), model, _c.ptr(qa), qa.size, _c.ptr(w)))
    return out


@dataclass
class Compensation:
    """Result of compensate_path (rows = points)."""

    q_cmd: np.ndarray              # (N, n) compensated joint path [rad]
    status: np.ndarray             # (N,) POINT_* bits
    q_nominal: Optional[np.ndarray] = None  # (N, n) IK of the nominal path (unloaded)
    pose_cmd: Optional[np.ndarray] = None   # (N, 4, 4) FK(q_cmd): compensated Cartesian targets

    def problems(self) -> list[tuple[int, str]]:
        """(index, description) of every point with a non-zero status."""
        return [(int(i), status_text(s)) for i, s in enumerate(self.status) if s]


def compensate_path(model: Model, poses, wrench, q_start=None, *, nominal: bool = True,
                    targets: bool = True, chunk: int = 0, progress=None) -> Compensation:
    """Compensate a path of tool poses (N, 4, 4) under wrenches ((N, 6), (6,) or (3,)):
    joint targets q_cmd with FK(q_cmd) + d(q_cmd, W) = nominal (6-D). The branch is kept from
    q_start (default: 0 / middle of the limits). `nominal` also returns the unloaded IK path,
    `targets` the compensated Cartesian targets FK(q_cmd). `chunk` > 0 splits the work (the
    branch carries over) and calls progress(done, total) after every chunk."""
    p = _poses(poses)
    rows, n = p.shape[0], model.robot.dof
    w = _wrench_rows(wrench, rows)
    q_cmd = np.empty((rows, n))
    status = np.zeros(rows, dtype=np.intc)
    q_nom = np.empty((rows, n)) if nominal else None
    start = None if q_start is None else _c.as_array(q_start).copy()
    step = chunk if chunk and chunk > 0 else max(rows, 1)
    needed = C.c_size_t()
    for a in range(0, rows, step):
        b = min(rows, a + step)
        pa, wa = np.ascontiguousarray(p[a:b]), np.ascontiguousarray(w[a:b])
        qa = np.empty((b - a, n))
        sa = np.zeros(b - a, dtype=np.intc)
        sp = None if start is None else _c.ptr(start)
        check(lib.stiff_compensate_path(_c.ptr(qa), qa.size, C.byref(needed),
                                        sa.ctypes.data_as(_c.c_int_p), model, _c.ptr(pa),
                                        _c.ptr(wa), b - a, sp))
        if nominal:
            qn = np.empty((b - a, n))
            check(lib.stiff_ik_path(_c.ptr(qn), qn.size, C.byref(needed), None, model.robot,
                                    _c.ptr(pa), b - a, sp))
            q_nom[a:b] = qn
        start = (qn[-1] if nominal else qa[-1]).copy()
        q_cmd[a:b], status[a:b] = qa, sa
        if progress is not None:
            progress(b, rows)
    out = Compensation(q_cmd, status.astype(np.int64), q_nom)
    if targets:
        out.pose_cmd = tool_poses(model.robot, q_cmd)
    return out


def truth_deviation(robot: Robot, truth, q, poses, wrench) -> np.ndarray:
    """(N, 6) deviation (position [m], rotation [rad]) of the loaded tool from the nominal
    poses with the joints at q, on the virtual robot whose truth is the YAML file `truth`:
    FK(q) + d_truth(q, W) - nominal."""
    from .data import find

    truth = find("truths", truth)
    p = _poses(poses)
    rows = p.shape[0]
    qa = np.ascontiguousarray(np.atleast_2d(q), dtype=np.float64)
    w = _wrench_rows(wrench, rows)
    out = np.empty((rows, 6))
    needed = C.c_size_t()
    check(lib.stiff_truth_deviation(_c.ptr(out), out.size, C.byref(needed), robot,
                                    _c.encode(os.fspath(truth)), _c.ptr(qa), _c.ptr(p),
                                    _c.ptr(w), rows))
    return out


def plot_deviation(path_xyz: np.ndarray, curves: dict, output, title: str = "") -> None:
    """Plot a path (top view, coloured by the first curve) and the deviation norm of every
    curve along it (label -> (N,) deviation [m]) into a PNG (matplotlib, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xyz = np.asarray(path_xyz) * 1e3
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4.8), gridspec_kw={"width_ratios": [1, 1.6]})
    first = next(iter(curves.values())) if curves else np.zeros(len(xyz))
    sc = ax0.scatter(xyz[:, 0], xyz[:, 1], c=np.asarray(first) * 1e6, s=4, cmap="viridis")
    fig.colorbar(sc, ax=ax0, label=f"{next(iter(curves), 'deviation')} [um]")
    ax0.set_xlabel("x [mm]")
    ax0.set_ylabel("y [mm]")
    ax0.set_aspect("equal", adjustable="datalim")
    ax0.set_title("path (base frame, top view)")
    idx = np.arange(len(xyz))
    for label, dev in curves.items():
        d = np.maximum(np.asarray(dev) * 1e6, 1e-6)
        ax1.semilogy(idx, d, label=f"{label} (max {d.max():.3g} um)")
    ax1.set_xlabel("point")
    ax1.set_ylabel("|position deviation| [um]")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    ax1.set_title(title or "deviation of the loaded tool from the nominal path")
    fig.tight_layout()
    from ._outputs import save_figure

    try:
        save_figure(fig, output, dpi=110)
    finally:
        plt.close(fig)
