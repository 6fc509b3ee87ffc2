"""A compensating wrapper around any RoboDK post-processor (docs/olp.md, section RoboDK).

RoboDK post-processors are Python classes that receive the program as calls: setFrame(pose),
setTool(pose), setSpeed(mm/s), RunCode(code), MoveJ(pose, joints, conf), MoveL(...),
MoveC(...), with poses as robomath.Mat in mm and joints in degrees. CompensatingPost wraps an
instance: it forwards every call, and before a motion reaches the wrapped post it replaces the
target by the compensated one (stiff_filter_target), so the wrapped post writes compensated
numbers in its own syntax. Process force: a per-motion force file, or the Kienzle milling
model fed by setSpeed (feed) and the spindle speed found in RunCode ("M3 S12000",
"SPINDLE_ON 12000", ...); joint (MoveJ) moves and moves with the spindle off carry none."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import Optional

import numpy as np

from .cutting import milling_wrench
from .program import ToolLoad, _weight_wrench
from .target import JointMap, filter_target

__all__ = ["CompensatingPost", "PostMotion", "compensating_post_class"]

_SPINDLE_ON = re.compile(r"\b(?:M0?3|M0?4|SPINDLE[_ ]?ON)\b", re.IGNORECASE)
_SPINDLE_OFF = re.compile(r"\b(?:M0?5|SPINDLE[_ ]?OFF)\b", re.IGNORECASE)
_RPM = re.compile(r"(?:\bS|SPINDLE[_ ]?ON\s*\(?\s*)(\d+(?:\.\d+)?)", re.IGNORECASE)


def _six(v) -> np.ndarray:
    """A force (3) or wrench (6) as a wrench, zero moment when not given."""
    a = np.asarray(v, dtype=float).ravel()
    if a.size not in (3, 6):
        raise ValueError(f"a wrench has 3 or 6 values, got {a.size}")
    return np.concatenate([a, np.zeros(6 - a.size)])


def _mat_to_np(pose) -> np.ndarray:
    t = np.array(pose.rows if hasattr(pose, "rows") else pose, dtype=float)
    t = t.reshape(4, 4).copy()
    t[:3, 3] *= 1e-3
    return t


def _np_to_mat(t: np.ndarray):
    from robodk import robomath

    m = t.copy()
    m[:3, 3] *= 1e3
    return robomath.Mat(m.tolist())


@dataclass
class PostMotion:
    """What the wrapper did with one motion (SI, reference frame at the TCP)."""

    kind: str
    wrench: np.ndarray
    deflection: np.ndarray
    pose_nominal: np.ndarray
    pose_cmd: np.ndarray
    q_cmd: np.ndarray
    status: int


class CompensatingPost:
    """Wrap `post` (an instance of a RoboDK post-processor class).

    model: stiff Model; force_file: {motion number (1-based, MoveL/MoveC only): (F [N], M
    [N*m]) in the reference frame}; milling: (KienzleMaterial, MillingCut) whose feed per tooth
    is replaced by speed / (spindle rpm * teeth) when both are known; tool_load: ToolLoad
    whose weight is added to every motion; joint_map: RoboDK/controller joints from the robot
    file's."""

    def __init__(self, post, model, *, force=None, force_file: Optional[dict] = None,
                 milling: Optional[tuple] = None, tool_load: Optional[ToolLoad] = None,
                 joint_map: Optional[JointMap] = None):
        self._post = post
        self._model = model
        self._force = None if force is None else _six(force)
        self._forces = force_file or {}
        self._milling = milling
        self._load = tool_load
        self._map = joint_map or JointMap()
        self._frame = np.eye(4)
        self._tool = np.eye(4)
        self._speed = None        # mm/s
        self._rpm = None
        self._spindle = False
        self._previous = None     # previous TCP position, reference frame [m]
        self._q = None
        self._process_count = 0
        self.motions: list[PostMotion] = []

    # ------------------------------------------------------------- forwarded state
    def __getattr__(self, name):
        return getattr(self._post, name)

    def setFrame(self, pose, frame_id=None, frame_name=None):
        self._frame = _mat_to_np(pose)
        self._previous = None
        return self._post.setFrame(pose, frame_id, frame_name)

    def setTool(self, pose, tool_id=None, tool_name=None):
        self._tool = _mat_to_np(pose)
        return self._post.setTool(pose, tool_id, tool_name)

    def setSpeed(self, speed_mms):
        self._speed = float(speed_mms)
        return self._post.setSpeed(speed_mms)

    def RunCode(self, code, is_function_call=False):
        text = str(code)
        if _SPINDLE_OFF.search(text):
            self._spindle = False
        elif _SPINDLE_ON.search(text):
            self._spindle = True
        m = _RPM.search(text)
        if m and self._spindle:
            self._rpm = float(m.group(1))
        return self._post.RunCode(code, is_function_call)

    # ------------------------------------------------------------------ motions
    def _wrench(self, kind: str, pose: np.ndarray, q) -> np.ndarray:
        w = np.zeros(6)
        if kind != "MoveJ":
            self._process_count += 1
            if self._process_count in self._forces:
                w[:] = _six(self._forces[self._process_count])
            elif self._spindle:
                if self._force is not None:
                    w += self._force
                if self._milling is not None:
                    material, cut = self._milling
                    if self._speed and self._rpm:
                        cut = replace(cut, feed_per_tooth=self._speed * 60.0 /
                                      (self._rpm * cut.teeth))
                    w += milling_wrench(material, cut, pose, self._previous)
        if self._load is not None:
            frames = SimpleNamespace(base=self._frame, tool=self._tool)
            w += _weight_wrench(frames, pose, self._load)
        return w

    def _compensate(self, kind: str, pose, joints):
        t = _mat_to_np(pose)
        seed = None
        if joints is not None and len(joints) >= self._model.robot.dof:
            seed = self._map.from_vendor(list(joints)[:self._model.robot.dof])
        elif self._q is not None:
            seed = self._q
        w = self._wrench(kind, t, seed)
        ft = filter_target(self._model, t, seed, w, self._frame, self._tool)
        self._previous = t[:3, 3]
        self._q = ft.q
        self.motions.append(PostMotion(kind, w, ft.deflection, t, ft.pose, ft.q, ft.status))
        new_joints = joints
        if joints is not None:
            new_joints = list(joints)
            new_joints[:ft.q.size] = [float(v) for v in self._map.to_vendor(ft.q)]
            if hasattr(joints, "tolist") or hasattr(joints, "rows"):
                from robodk import robomath

                new_joints = robomath.Mat(new_joints) if hasattr(joints, "rows") else new_joints
        return _np_to_mat(ft.pose), new_joints

    def MoveJ(self, pose, joints, conf_RLF=None):
        if pose is None:  # a joint move without a Cartesian target: nothing to compensate
            return self._post.MoveJ(pose, joints, conf_RLF)
        p, j = self._compensate("MoveJ", pose, joints)
        return self._post.MoveJ(p, j, conf_RLF)

    def MoveL(self, pose, joints, conf_RLF=None):
        if pose is None:
            return self._post.MoveL(pose, joints, conf_RLF)
        p, j = self._compensate("MoveL", pose, joints)
        return self._post.MoveL(p, j, conf_RLF)

    def MoveC(self, pose1, joints1, pose2, joints2, conf_RLF_1=None, conf_RLF_2=None):
        p1, j1 = self._compensate("MoveC", pose1, joints1)
        p2, j2 = self._compensate("MoveC", pose2, joints2)
        return self._post.MoveC(p1, j1, p2, j2, conf_RLF_1, conf_RLF_2)


def compensating_post_class(post_class, model, **options):
    """A RobotPost class for a RoboDK post-processor file: instances are `post_class`
    instances wrapped in CompensatingPost(model, **options). In the post file:

        from KUKA_KRC4 import RobotPost as VendorPost   # any post RoboDK ships or yours
        RobotPost = compensating_post_class(VendorPost, model, milling=(material, cut))
    """

    class RobotPost:
        def __new__(cls, *args, **kwargs):
            return CompensatingPost(post_class(*args, **kwargs), model, **options)

    RobotPost.__name__ = f"Compensating{post_class.__name__}"
    return RobotPost
