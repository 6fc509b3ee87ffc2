"""Vendor pose conventions (docs/olp.md): position in mm, orientation as each controller
writes it. Everything returned is a 4 x 4 transform in metres.

- KUKA KRL: {X, Y, Z, A, B, C}, A about Z, then B about the new Y, then C about the new X
  (R = Rz(A) Ry(B) Rx(C)), degrees.
- ABB RAPID: quaternion [q1, q2, q3, q4] = [w, x, y, z] (unit norm).
- Fanuc: X Y Z W P R, W about the fixed X, P about the fixed Y, R about the fixed Z
  (R = Rz(R) Ry(P) Rx(W)), degrees."""
from __future__ import annotations

import math

import numpy as np

MM = 1e-3


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def transform(r: np.ndarray, p_m) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = r
    t[:3, 3] = p_m
    return t


def zyx_angles(r: np.ndarray) -> tuple[float, float, float]:
    """(a, b, c) [rad] with R = Rz(a) Ry(b) Rx(c); b in [-pi/2, pi/2]."""
    b = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.cos(b) < 1e-12:  # gimbal lock: put the whole rotation about the vertical into a
        a = math.atan2(-r[0, 1], r[1, 1])
        return a, b, 0.0
    return math.atan2(r[1, 0], r[0, 0]), b, math.atan2(r[2, 1], r[2, 2])


def nearest_deg(angle_deg: float, reference_deg: float) -> float:
    """The angle in (-180, 180] as controllers want it, except that an angle at the +-180
    seam keeps the sign the program wrote (180 stays 180, -180 stays -180)."""
    a = math.remainder(angle_deg, 360.0)
    if abs(abs(a) - 180.0) < 1e-9 and abs(abs(reference_deg) - 180.0) < 1e-9:
        return math.copysign(180.0, reference_deg)
    return 180.0 if a == -180.0 else a


# ------------------------------------------------------------------------------ KUKA
def kuka_to_pose(x, y, z, a, b, c) -> np.ndarray:
    r = rot_z(math.radians(a)) @ rot_y(math.radians(b)) @ rot_x(math.radians(c))
    return transform(r, np.array([x, y, z], dtype=float) * MM)


def pose_to_kuka(t: np.ndarray, reference=None) -> list[float]:
    a, b, c = (math.degrees(v) for v in zyx_angles(t[:3, :3]))
    out = [*(t[:3, 3] / MM), a, b, c]
    if reference is not None:
        out[3:] = [nearest_deg(v, float(ref)) for v, ref in zip(out[3:], reference[3:])]
    return [float(v) for v in out]


# ------------------------------------------------------------------------------- ABB
def quat_to_rot(q) -> np.ndarray:
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if abs(n - 1.0) > 1e-3:
        raise ValueError(f"quaternion {list(q)} is not normalised (norm {n:.6f})")
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def rot_to_quat(r: np.ndarray, reference=None) -> list[float]:
    """[w, x, y, z]; of the two signs, the one nearest `reference` (default w >= 0)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q) / np.linalg.norm(q)
    ref = np.array([1.0, 0, 0, 0]) if reference is None else np.asarray(reference, dtype=float)
    if float(q @ ref) < 0:
        q = -q
    return [float(v) for v in q]


def abb_to_pose(xyz, quat) -> np.ndarray:
    return transform(quat_to_rot(quat), np.asarray(xyz, dtype=float) * MM)


def pose_to_abb(t: np.ndarray, reference_quat=None) -> tuple[list[float], list[float]]:
    return [float(v) for v in t[:3, 3] / MM], rot_to_quat(t[:3, :3], reference_quat)


# ----------------------------------------------------------------------------- Fanuc
def fanuc_to_pose(x, y, z, w, p, r) -> np.ndarray:
    rot = rot_z(math.radians(r)) @ rot_y(math.radians(p)) @ rot_x(math.radians(w))
    return transform(rot, np.array([x, y, z], dtype=float) * MM)


def pose_to_fanuc(t: np.ndarray, reference=None) -> list[float]:
    rz, ry, rx = (math.degrees(v) for v in zyx_angles(t[:3, :3]))
    out = [*(t[:3, 3] / MM), rx, ry, rz]
    if reference is not None:
        out[3:] = [nearest_deg(v, float(ref)) for v, ref in zip(out[3:], reference[3:])]
    return [float(v) for v in out]
