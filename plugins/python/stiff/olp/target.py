"""One program target through the compensation: the FilterTarget-shaped call of the C ABI
(stiff_filter_target) and the arm configuration a controller stores beside a Cartesian target
(docs/olp.md)."""
from __future__ import annotations

import ctypes as C
import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from .. import _capi as _c
from .._capi import check, lib
from ..api import Model, Robot
from ..compensate import tool_poses

__all__ = ["FilteredTarget", "filter_target", "JointMap", "ArmGeometry", "Configuration",
           "POINT_CONFIG_CHANGE"]

#: Status bit of a target whose compensated joints are in another arm configuration (or turn)
#: than the nominal ones; the program filters treat it as an error.
POINT_CONFIG_CHANGE = 32


@dataclass
class FilteredTarget:
    """Result of filter_target (SI, the program's reference frame)."""

    pose: np.ndarray        # (4, 4) compensated TCP pose (the input pose when not compensated)
    q: np.ndarray           # (n,) compensated joints [rad]
    status: int             # POINT_* bits
    deflection: np.ndarray  # (6,) predicted TCP deflection at the nominal joints [m, rad]


def _frame(t) -> Optional[np.ndarray]:
    if t is None:
        return None
    a = np.ascontiguousarray(t, dtype=np.float64)
    if a.shape != (4, 4):
        raise ValueError(f"a frame must be a 4 x 4 transform, got shape {a.shape}")
    return a


def filter_target(model: Model, pose, q_seed=None, wrench=None, base=None,
                  tool=None) -> FilteredTarget:
    """Compensated target for a programmed TCP pose (4 x 4, m, in the reference frame `base`,
    itself given in the robot base frame; `tool`: TCP in the flange frame). `wrench`: process
    force [N] (and moment [N*m]) at the TCP in reference-frame components; `q_seed`: joints
    near which the nominal solution is taken. Wraps stiff_filter_target."""
    n = model.robot.dof
    p = _frame(pose)
    if p is None:
        raise ValueError("pose is required")
    b, t = _frame(base), _frame(tool)
    seed = None if q_seed is None else _c.as_array(q_seed)
    if seed is not None and seed.size != n:
        raise ValueError(f"q_seed has {seed.size} values for a {n}-joint robot")
    w = None
    if wrench is not None:
        w = np.zeros(6)
        wa = np.asarray(wrench, dtype=float).ravel()
        if wa.size not in (3, 6):
            raise ValueError(f"wrench must have 3 or 6 values, has {wa.size}")
        w[:wa.size] = wa
    out, q, d = np.empty((4, 4)), np.empty(n), np.empty(6)
    st, needed = C.c_int(0), C.c_size_t(0)
    check(lib.stiff_filter_target(_c.ptr(out), _c.ptr(q), n, C.byref(needed), C.byref(st),
                                  _c.ptr(d), model, _c.ptr(p),
                                  None if seed is None else _c.ptr(seed),
                                  None if w is None else _c.ptr(w),
                                  None if b is None else _c.ptr(b),
                                  None if t is None else _c.ptr(t)))
    return FilteredTarget(out, q, int(st.value), d)


@dataclass
class JointMap:
    """Controller joint angles from the robot file's: vendor_deg = sign * deg(q) + offset_deg.
    Identity by default (the robot file follows the controller's zeros and directions)."""

    sign: Sequence[float] = field(default_factory=lambda: [1.0] * 6)
    offset_deg: Sequence[float] = field(default_factory=lambda: [0.0] * 6)

    def to_vendor(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        return np.asarray(self.sign[:q.size]) * np.degrees(q) + np.asarray(self.offset_deg[:q.size])

    def from_vendor(self, deg) -> np.ndarray:
        d = np.asarray(deg, dtype=float)
        return np.radians((d - np.asarray(self.offset_deg[:d.size])) / np.asarray(self.sign[:d.size]))

    @classmethod
    def parse(cls, text: str) -> "JointMap":
        """'s1:o1,s2:o2,...' e.g. '-1:0,1:-90,1:90,-1:0,1:0,-1:0' (sign:offset_deg per joint)."""
        sign, off = [], []
        for i, part in enumerate(text.split(",")):
            try:
                s, o = part.split(":")
                sign.append(float(s))
                off.append(float(o))
            except ValueError:
                raise ValueError(f"joint map entry {i + 1} '{part}': expected sign:offset_deg")
            if abs(abs(sign[-1]) - 1) > 0:
                raise ValueError(f"joint map entry {i + 1}: sign must be 1 or -1")
        return cls(sign, off)


class ArmGeometry:
    """Wrist centre and elbow reference of a 6R arm with a spherical wrist, found numerically
    from the forward kinematics (so the joint convention of the robot file does not matter):

    - the wrist centre c(q) = p(q) - R(q) v, v constant in the tool frame (the point that does
      not move when joints 4-6 move);
    - shoulder: the wrist centre in front of axis 1 when it is on the side where it is at
      q2 = q3 = 0 (same q1);
    - elbow: |c - axis 2|^2 = A + B cos q3 + C sin q3 (law of cosines), so the stretched arm
      is at q3* = atan2(C, B); 'up' is the side of q3* on which the canonical pose lies (upper
      arm vertical, forearm horizontal, wrist centre in front: the zero of ABB and Fanuc arms,
      KUKA's A2 = -90, A3 = 90 deg), found from the geometry, not from the joint zeros;
    - wrist: the sign of joint 5 (axes 4 and 6 aligned at q5 = 0)."""

    def __init__(self, robot: Robot):
        self.robot = robot
        n = robot.dof
        if n != 6:
            raise ValueError(f"arm configurations need a 6-joint robot, {robot.name} has {n}")
        rng = np.random.default_rng(7)
        qs = np.zeros((6, 6))
        qs[:, 3:] = rng.uniform(-1.2, 1.2, (6, 3))
        t = tool_poses(robot, qs)
        # p_i - R_i v equal for all i: (R_i - R_0) v = p_i - p_0.
        a = np.vstack([t[i, :3, :3] - t[0, :3, :3] for i in range(1, 6)])
        b = np.concatenate([t[i, :3, 3] - t[0, :3, 3] for i in range(1, 6)])
        self.v = np.linalg.lstsq(a, b, rcond=None)[0]
        spread = np.linalg.norm(a @ self.v - b)
        if spread > 1e-9:
            raise ValueError(f"{robot.name}: the last three axes do not intersect (spherical-wrist"
                             f" residual {spread:.2e} m); arm configurations need a spherical wrist")
        # Axis 1: the circle the wrist centre draws when q1 moves (arm bent so that it is off
        # the axis).
        pts = [self.centre(np.array([a1, 0.3, 0.2, 0, 0, 0.0])) for a1 in (-0.4, 0.1, 0.6)]
        self.axis1_point = _circumcentre(*pts)
        nrm = np.cross(pts[1] - pts[0], pts[2] - pts[0])
        self.axis1_dir = nrm / np.linalg.norm(nrm)
        # Axis 2: centre of the circle the wrist centre draws when q2 moves.
        pts = [self.centre(np.array([0, a2, 0, 0, 0, 0.0])) for a2 in (-0.4, 0.1, 0.6)]
        self.axis2_point = _circumcentre(*pts)
        d2 = []
        for q3 in (0.0, 2 * math.pi / 3, 4 * math.pi / 3):
            c = self.centre(np.array([0, 0, q3, 0, 0, 0.0]))
            d2.append(float(np.sum((c - self.axis2_point) ** 2)))
        # d2 = A + B cos q3 + C sin q3 at three angles.
        m = np.array([[1, math.cos(x), math.sin(x)] for x in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)])
        _, bb, cc = np.linalg.solve(m, d2)
        self.q3_stretched = math.atan2(cc, bb)
        # Which side of the stretched arm is 'up': the side of the canonical pose with the upper
        # arm vertical and the forearm horizontal, wrist centre in front (ABB and Fanuc zero,
        # KUKA's A2 = -90, A3 = 90 deg): anchored in the geometry, not in the joint zeros.
        up = self.axis1_dir if self.axis1_dir[2] >= 0 else -self.axis1_dir
        best, q2v = -np.inf, 0.0
        for a2 in np.linspace(-math.pi, math.pi, 73):
            e = self._elbow(np.array([0, a2, 0, 0, 0, 0.0]))
            r = e - self.axis2_point
            h = float(r @ up) / max(float(np.linalg.norm(r)), 1e-12)
            if h > best:
                best, q2v = h, a2
        self.elbow_sign = 1.0
        for cand in (self.q3_stretched + math.pi / 2, self.q3_stretched - math.pi / 2):
            if self.front(np.array([0, q2v, cand, 0, 0, 0.0])):
                self.elbow_sign = 1.0 if _wrap(cand - self.q3_stretched) >= 0 else -1.0
                break

    def _elbow(self, q) -> np.ndarray:
        """A point on axis 3: the centre of the circle the wrist centre draws about it."""
        pts = []
        for dq in (-0.3, 0.0, 0.3):
            v = np.array(q, dtype=float)
            v[2] += dq
            pts.append(self.centre(v))
        return _circumcentre(*pts)

    def centre(self, q) -> np.ndarray:
        t = tool_poses(self.robot, np.asarray(q, dtype=float))[0]
        return t[:3, 3] - t[:3, :3] @ self.v

    def front(self, q) -> bool:
        q = np.asarray(q, dtype=float)
        c = self.centre(q)
        ref = q.copy()
        ref[1] = ref[2] = 0.0
        c0 = self.centre(ref)
        return float(c[:2] @ c0[:2]) >= 0.0

    def elbow_up(self, q) -> bool:
        return _wrap(float(q[2]) - self.q3_stretched) * self.elbow_sign >= 0.0

    def wrist_positive(self, q) -> bool:
        return float(q[4]) >= 0.0


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _circumcentre(a, b, c) -> np.ndarray:
    ab, ac = b - a, c - a
    n = np.cross(ab, ac)
    return a + (np.cross(n, ab) * (ac @ ac) + np.cross(ac, n) * (ab @ ab)) / (2 * (n @ n))


@dataclass(frozen=True)
class Configuration:
    """Arm configuration of a joint vector: shoulder (wrist centre in front of axis 1), elbow,
    wrist (joint 5 sign) and the controller's joint angles [deg] from which turns follow."""

    front: bool
    elbow_up: bool
    wrist_positive: bool
    vendor_deg: tuple

    @classmethod
    def of(cls, geometry: ArmGeometry, q, joint_map: JointMap) -> "Configuration":
        v = joint_map.to_vendor(q)
        # The wrist sign in controller terms: joint 5's direction may be flipped by the map.
        wrist = (v[4] >= 0.0)
        return cls(geometry.front(q), geometry.elbow_up(q), bool(wrist), tuple(float(x) for x in v))

    def same_arm(self, other: "Configuration") -> bool:
        return (self.front, self.elbow_up, self.wrist_positive) == \
            (other.front, other.elbow_up, other.wrist_positive)

    # -- KUKA: Status bit 0 overhead (wrist centre behind axis 1), bit 1 elbow (A3 >= stretched
    # angle), bit 2 A5 <= 0; Turn bit i set when A(i+1) < 0.
    def kuka_status(self) -> int:
        return (0 if self.front else 1) | (2 if self.elbow_up else 0) | \
            (4 if self.vendor_deg[4] <= 0 else 0)

    def kuka_turn(self) -> int:
        return sum(1 << i for i, a in enumerate(self.vendor_deg[:6]) if a < 0)

    # -- ABB: cf1, cf4, cf6 = quadrant floor(angle / 90 deg); cfx = 4 * (behind axis 1) +
    # 2 * (behind the lower arm: elbow down) + (axis 5 negative).
    def abb_confdata(self) -> list[int]:
        v = self.vendor_deg
        cfx = (0 if self.front else 4) + (0 if self.elbow_up else 2) + (1 if v[4] < 0 else 0)
        return [math.floor(v[0] / 90.0), math.floor(v[3] / 90.0), math.floor(v[5] / 90.0), cfx]

    # -- Fanuc: 'F|N U|D T|B, t1, t4, t6': flip when J5 > 0, up/down elbow, top when the
    # wrist centre is in front of axis 1; turn t = 0 for -180 < J <= 180, +-1 per further turn.
    def fanuc_config(self) -> tuple[str, str, str, int, int, int]:
        v = self.vendor_deg

        def turn(a: float) -> int:
            return int(math.ceil((a - 180.0) / 360.0))

        return ("F" if v[4] > 0 else "N", "U" if self.elbow_up else "D",
                "T" if self.front else "B", turn(v[0]), turn(v[3]), turn(v[5]))
