"""Program filter engine shared by the vendor formats (docs/olp.md).

A format parser turns a program into Targets: every motion target with its vendor numbers and
the character spans those numbers occupy in the file, the frames active at the motion and the
motion kind. The engine compensates each target with filter_target under the wrench of its
motion and asks the format to print the new numbers; the writer then replaces exactly those
spans, so every other byte of the program stays as it was."""
from __future__ import annotations

import csv
import ctypes as C
import math
import os
import tempfile
from dataclasses import dataclass, field, replace
from typing import Optional, Sequence

import numpy as np

from .. import _capi as _c
from .._capi import check, lib
from ..api import Model, Robot
from ..compensate import (POINT_NOT_CONVERGED, POINT_SINGULAR, POINT_UNREACHABLE,
                          inverse_kinematics, tool_poses)
from ..errors import StiffError
from .cutting import milling_wrench
from .target import POINT_CONFIG_CHANGE, ArmGeometry, Configuration, JointMap, filter_target

__all__ = ["FilterError", "ToolLoad", "Target", "Program", "WrenchSpec", "FilterOptions",
           "TargetReport", "FilterResult", "filter_program", "GRAVITY", "tool_points",
           "POINT_NEAR_SINGULAR"]

GRAVITY = np.array([0.0, 0.0, -9.80665])  # robot base frame, z up
#: Status bit: within the singularity margin (wrist, elbow or shoulder) of FilterOptions.
POINT_NEAR_SINGULAR = 64


class FilterError(ValueError):
    """A program cannot be filtered; the message names file:line and the reason."""


@dataclass
class ToolLoad:
    mass: float                # kg
    cog: np.ndarray            # centre of gravity in the flange frame [m]


@dataclass
class Target:
    """One motion target of a program (vendor numbers and where they are written)."""

    file: str                  # key of Program.texts
    line: int                  # 1-based line of the motion instruction
    name: str                  # label (variable name, P[n], 'inline')
    motion: str                # instruction as written (LIN, MoveL, L, ...)
    process: bool              # a cutting/process move (linear or circular); else air
    joint: bool                # joint target (vendor joint angles [deg])
    values: list               # vendor numbers: x, y, z [mm] + orientation, or joints [deg]
    spans: list                # (file, start, end) of every value, same order as values
    base: np.ndarray           # reference frame in the robot base frame
    tool: np.ndarray           # TCP in the flange frame
    load: Optional[ToolLoad] = None
    config: object = None      # format-specific configuration as written (None: not given)
    config_spans: list = field(default_factory=list)
    speed: Optional[float] = None  # programmed TCP speed [m/s]
    decl_line: int = 0         # line of the declaration (data file) when not inline
    decl_file: str = ""
    program_text: dict = field(default_factory=dict, repr=False)  # key -> text, for printing


# Joint angles and quaternion components are written with this many more decimals than
# positions: 1e-9 deg keeps 1e-9 m at a metre of reach.
ANGLE_EXTRA_DECIMALS = 3


def format_numbers(t: Target, values, min_decimals: int, extra=lambda i: 0) -> list:
    """The new values of t's numbers as text: at least `min_decimals` (+ extra(i) for number i)
    decimals and never fewer than the program wrote; a zero is written 0.000..., never -0."""
    out = []
    for i, ((f, a, b), v) in enumerate(zip(t.spans, values)):
        old = t.program_text[f][a:b]
        d = max(min_decimals + extra(i), len(old.split(".")[1]) if "." in old else 0)
        s = f"{v:.{d}f}"
        out.append("0." + "0" * d if float(s) == 0 else s)
    return out


def parse_numbers(t: Target, texts) -> list:
    """The numbers as a program reader sees them (the written text read back)."""
    return [float(s) for s in texts]


class DecimalNumbers:
    """A format whose target numbers are plain decimals: joint angles written with
    ANGLE_EXTRA_DECIMALS more decimals than positions, read back as written."""

    @staticmethod
    def format_values(t: Target, values, min_decimals: int) -> list:
        return format_numbers(t, values, min_decimals,
                              lambda i: ANGLE_EXTRA_DECIMALS if t.joint else 0)

    @staticmethod
    def parse_values(t: Target, texts) -> list:
        return parse_numbers(t, texts)


class Program:
    """Texts of a program's files and its targets; `fmt` prints and parses the numbers."""

    def __init__(self, fmt, paths: dict, texts: dict, targets: list):
        self.fmt = fmt
        self.paths = paths    # key -> input path
        self.texts = texts    # key -> text
        self.targets = targets

    def rewrite(self, replacements: list) -> dict:
        """New texts: (file, start, end, text) replacements applied; spans must not overlap."""
        out = {}
        for key, text in self.texts.items():
            reps = sorted([r for r in replacements if r[0] == key], key=lambda r: r[1])
            parts, pos = [], 0
            for _, a, b, s in reps:
                if a < pos:
                    raise FilterError(f"{self.paths[key]}: overlapping replacements at {a}")
                parts.append(text[pos:a])
                parts.append(s)
                pos = b
            parts.append(text[pos:])
            out[key] = "".join(parts)
        return out


@dataclass
class WrenchSpec:
    """Where the wrench of each motion comes from (reference-frame components, at the TCP).

    force: constant process force [N] (3 or 6 values with moment [N*m]) on process moves;
    force_file: CSV `target,fx_N,fy_N,fz_N[,mx_Nm,my_Nm,mz_Nm]` per target number (1-based,
    the report's numbering), overriding the constant force for the targets it lists;
    milling: (material, cut) for the Kienzle model on process moves, directed along the
    motion (with spindle_rpm, the feed per tooth of each motion follows from its programmed
    speed: f_z = v / (n z)); tool_weight: add the gravity of the program's tool load (or `tool_load`)."""

    force: Optional[Sequence[float]] = None
    force_file: Optional[str] = None
    milling: Optional[tuple] = None
    tool_weight: bool = False
    tool_load: Optional[ToolLoad] = None
    spindle_rpm: Optional[float] = None  # milling: f_z from each motion's programmed speed


@dataclass
class FilterOptions:
    joint_map: JointMap = field(default_factory=JointMap)
    min_decimals: int = 6             # mm and deg; quaternions get 3 more
    singular_margin_deg: float = 5.0  # wrist / elbow margin flagged near-singular
    shoulder_margin_m: float = 0.05   # wrist centre this close to axis 1
    q_start: Optional[Sequence[float]] = None
    allow_config_change: bool = False
    #: Stiffness-aware rotation about the tool axis of process paths (orient.py): the limit
    #: [deg], None = keep the programmed orientation; grid resolution and the largest change
    #: between consecutive targets [deg].
    tool_rotation_limit_deg: Optional[float] = None
    tool_rotation_resolution_deg: float = 5.0
    tool_rotation_max_step_deg: float = 10.0


@dataclass
class TargetReport:
    number: int
    file: str
    line: int
    name: str
    motion: str
    wrench: np.ndarray        # (6,) at the TCP, reference frame
    deflection: np.ndarray    # (6,) predicted TCP deflection of the nominal program [m, rad]
    correction: np.ndarray    # (3,) written - nominal TCP position [m]
    residual: float           # predicted TCP position error of the written program [m]
    status: int
    q_nominal: np.ndarray
    q_cmd: np.ndarray
    tool_rotation: float = 0.0  # rotation about the tool axis chosen for stiffness [rad]
    deflection_unrotated: float = float("nan")  # |deflection| [m] at the programmed rotation

    def flags(self) -> str:
        names = [(POINT_UNREACHABLE, "unreachable"), (POINT_SINGULAR, "singular"),
                 (POINT_NEAR_SINGULAR, "near-singular"), (POINT_NOT_CONVERGED, "not converged"),
                 (POINT_CONFIG_CHANGE, "configuration change")]
        return ", ".join(n for b, n in names if self.status & b) or "ok"


@dataclass
class FilterResult:
    program: Program
    texts: dict               # key -> filtered text
    targets: list             # TargetReport per target

    def write(self, directory) -> list:
        """Write every file of the program into `directory` under its own name (atomic per
        file: a temporary file renamed; an input file is never overwritten)."""
        os.makedirs(directory, exist_ok=True)
        written = []
        for key, text in self.texts.items():
            src = os.path.abspath(self.program.paths[key])
            dst = os.path.join(os.fspath(directory), os.path.basename(src))
            if os.path.abspath(dst) == src:
                raise FilterError(f"{dst}: the output would overwrite the input program; "
                                  "choose another directory")
            written.append((dst, text))
        for dst, text in written:
            fd, tmp = tempfile.mkstemp(dir=os.path.dirname(dst) or ".", suffix=".tmp")
            with os.fdopen(fd, "w", newline="", encoding="latin-1") as f:
                f.write(text)
            os.replace(tmp, dst)
        return [d for d, _ in written]

    def table(self) -> list[dict]:
        rows = []
        motions = next(iter(self.program.paths))
        for r in self.targets:
            rows.append({"target": r.number, "file": os.path.basename(self.program.paths[motions]),
                         "line": r.line, "name": r.name, "motion": r.motion,
                         "force_N": float(np.linalg.norm(r.wrench[:3])),
                         "deflection_um": float(np.linalg.norm(r.deflection[:3]) * 1e6),
                         "deflection_rot_urad": float(np.linalg.norm(r.deflection[3:]) * 1e6),
                         "correction_um": float(np.linalg.norm(r.correction) * 1e6),
                         "residual_um": float(r.residual * 1e6),
                         "tool_rotation_deg": float(np.degrees(r.tool_rotation)),
                         "deflection_unrotated_um": float(r.deflection_unrotated * 1e6),
                         "flags": r.flags()})
        return rows

    def summary(self) -> dict:
        t = self.table()
        d = [r["deflection_um"] for r in t] or [0.0]
        res = [r["residual_um"] for r in t] or [0.0]
        return {"targets": len(t), "max_deflection_um": max(d), "max_residual_um": max(res),
                "problems": [(r["target"], r["line"], r["flags"]) for r in t
                             if r["flags"] != "ok"]}


def tool_points(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(measured point, load point) of the robot file, flange frame [m]."""
    mp, lp = np.zeros(3), np.zeros(3)
    check(lib.stiff_robot_tool_points(_c.ptr(mp), _c.ptr(lp), robot))
    return mp, lp


def _inv(t: np.ndarray) -> np.ndarray:
    i = np.eye(4)
    i[:3, :3] = t[:3, :3].T
    i[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return i


def _trans(p) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = p
    return t


def _read_force_file(path) -> dict:
    out = {}
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise FilterError(f"{path}: no header")
    head = [h.strip() for h in rows[0]]
    want = ["target", "fx_N", "fy_N", "fz_N"]
    if head[:4] != want or head[4:] not in ([], ["mx_Nm", "my_Nm", "mz_Nm"]):
        raise FilterError(f"{path}:1: header must be target,fx_N,fy_N,fz_N[,mx_Nm,my_Nm,mz_Nm]")
    for i, r in enumerate(rows[1:], start=2):
        if len(r) != len(head):
            raise FilterError(f"{path}:{i}: {len(r)} fields, the header has {len(head)}")
        try:
            n = int(r[0])
            w = [float(v) for v in r[1:]]
        except ValueError as e:
            raise FilterError(f"{path}:{i}: {e}")
        if n < 1 or not all(map(math.isfinite, w)):
            raise FilterError(f"{path}:{i}: target numbers start at 1 and forces must be finite")
        out[n] = np.array(w + [0.0] * (6 - len(w)))
    return out


class _Engine:
    def __init__(self, model: Model, options: FilterOptions):
        self.model = model
        self.robot = model.robot
        self.o = options
        self.mp, self.lp = tool_points(self.robot)
        try:
            self.geometry = ArmGeometry(self.robot)
        except ValueError:
            # not a 6R arm with a spherical wrist: no configuration flags to compute or check;
            # targets take the solution nearest the previous one
            self.geometry = None
        lo, hi = self.robot.limits
        self.lo, self.hi = lo, hi

    def flange(self, q) -> np.ndarray:
        return tool_poses(self.robot, q)[0] @ _trans(-self.mp)

    def tcp_of_joints(self, q, t: Target) -> np.ndarray:
        return _inv(t.base) @ self.flange(q) @ t.tool

    def configuration(self, q) -> Optional[Configuration]:
        if self.geometry is None:
            return None
        return Configuration.of(self.geometry, q, self.o.joint_map)

    def solutions(self, pose_ref: np.ndarray, t: Target, seed) -> np.ndarray:
        mp_pose = t.base @ pose_ref @ _inv(t.tool) @ _trans(self.mp)
        try:
            sols = inverse_kinematics(self.robot, mp_pose, seed)
        except StiffError:
            return np.zeros((0, self.robot.dof))
        # Other turns of joints 1, 4 and 6 within the limits: turn flags select among them.
        out = []
        for s in sols:
            for k1 in (-1, 0, 1):
                for k4 in (-1, 0, 1):
                    for k6 in (-1, 0, 1):
                        q = s.copy()
                        if q.size >= 6:
                            q[0] += 2 * math.pi * k1
                            q[3] += 2 * math.pi * k4
                            q[5] += 2 * math.pi * k6
                        elif (k1, k4, k6) != (0, 0, 0):
                            continue
                        if np.all(q >= self.lo - 1e-12) and np.all(q <= self.hi + 1e-12):
                            out.append(q)
        out.sort(key=lambda q: float(np.linalg.norm(q - seed)))
        return np.array(out) if out else np.zeros((0, self.robot.dof))

    def matches(self, fmt, t: Target, q) -> bool:
        """Do the joints q have the configuration the program writes? A joint within 1e-6 rad
        of a turn or quadrant boundary matches either side (rounding of the program)."""
        if self.geometry is None or fmt.config_matches(t, self.configuration(q)):
            return True
        for j in (0, 3, 5):
            for eps in (-1e-6, 1e-6):
                v = np.array(q, dtype=float)
                v[j] += eps
                if fmt.config_matches(t, self.configuration(v)):
                    return True
        return False

    def near_singular(self, q) -> bool:
        if self.geometry is None:
            return False
        m = math.radians(self.o.singular_margin_deg)
        g = self.geometry
        if abs(float(q[4])) < m or abs(math.remainder(float(q[2]) - g.q3_stretched, 2 * math.pi)) < m:
            return True
        c = g.centre(q)
        return bool(np.linalg.norm(np.cross(c - g.axis1_point, g.axis1_dir)) < self.o.shoulder_margin_m)


def _weight_wrench(t: Target, pose_ref: np.ndarray, load: Optional[ToolLoad]) -> np.ndarray:
    """Weight of the tool load at the TCP, reference-frame components, with the tool at the
    target (the loaded state): F = m g, M = (p_cog - p_TCP) x F."""
    w = np.zeros(6)
    if load is None:
        return w
    tcp = t.base @ pose_ref
    fl = tcp @ _inv(t.tool)
    f = load.mass * GRAVITY
    cog = (fl @ np.append(load.cog, 1.0))[:3]
    rb = t.base[:3, :3]
    w[:3] = rb.T @ f
    w[3:] = rb.T @ np.cross(cog - tcp[:3, 3], f)
    return w


def _process_wrench(spec: WrenchSpec, t: Target, number: int, forces: dict, prev_pos,
                    pose_ref: np.ndarray) -> np.ndarray:
    w = np.zeros(6)
    if number in forces:
        return forces[number].copy()
    if not t.process:
        return w
    if spec.force is not None:
        f = np.asarray(spec.force, dtype=float)
        w[:f.size] = f
    if spec.milling is not None:
        material, cut = spec.milling
        if spec.spindle_rpm and t.speed:
            # feed per tooth from the programmed feed: f_z = v_f / (n z)
            cut = replace(cut, feed_per_tooth=t.speed * 1e3 * 60.0 / (spec.spindle_rpm * cut.teeth))
        w += milling_wrench(material, cut, pose_ref, prev_pos)
    return w


def filter_program(program: Program, model: Model, wrench: WrenchSpec,
                   options: Optional[FilterOptions] = None) -> FilterResult:
    """Compensate every target of a parsed program (see the module docstring)."""
    o = options or FilterOptions()
    eng = _Engine(model, o)
    fmt = program.fmt
    forces = _read_force_file(wrench.force_file) if wrench.force_file else {}
    n = model.robot.dof
    prev_q = (np.asarray(o.q_start, dtype=float) if o.q_start is not None
              else 0.5 * (eng.lo + eng.hi))
    prev_pos, prev_base = None, None
    motions = next(iter(program.paths))  # the file with the motion instructions
    # Pass 1: nominal pose, joints and wrench of every target.
    plan = []
    for number, t in enumerate(program.targets, start=1):
        where = f"{program.paths[motions]}:{t.line}"
        if t.joint:
            q_nom = o.joint_map.from_vendor(t.values)
            if q_nom.size != n:
                raise FilterError(f"{where}: {q_nom.size} joint values for a {n}-joint robot")
            pose_ref = eng.tcp_of_joints(q_nom, t)
        else:
            pose_ref = fmt.pose_of(t)
            sols = eng.solutions(pose_ref, t, prev_q)
            q_nom = None
            for s in sols:
                if t.config is None or eng.matches(fmt, t, s):
                    q_nom = s
                    break
            if q_nom is None and len(sols):
                raise FilterError(f"{where}: target {t.name}: no inverse kinematics solution "
                                  f"in the configuration the program gives ({fmt.config_text(t)})")
        if prev_base is not t.base:
            prev_pos = None  # a new reference frame: no feed direction from the last target
        w_process = _process_wrench(wrench, t, number, forces, prev_pos, pose_ref)
        load = (wrench.tool_load or t.load) if wrench.tool_weight else None
        w = w_process + _weight_wrench(t, pose_ref, load)
        prev_pos, prev_base = pose_ref[:3, 3], t.base
        if q_nom is not None:
            prev_q = q_nom
        plan.append([t, pose_ref, q_nom, w, 0.0, float("nan"), w_process, load])
    if o.tool_rotation_limit_deg:
        _rotate_paths(plan, eng, fmt, o)
    # Pass 2: compensate and print.
    reps, reports, done = [], [], {}
    for number, (t, pose_ref, q_nom, w, psi, d0, _, _) in enumerate(plan, start=1):
        where = f"{program.paths[motions]}:{t.line}"
        if q_nom is None:
            reports.append(TargetReport(number, t.file, t.line, t.name, t.motion, w, np.zeros(6),
                                        np.zeros(3), float("nan"), POINT_UNREACHABLE,
                                        np.full(n, np.nan), np.full(n, np.nan), psi))
            continue
        key = (t.file, t.spans[0][1]) if t.spans else None
        ft = filter_target(model, pose_ref, q_nom, w, t.base, t.tool)
        status = ft.status
        if eng.near_singular(ft.q):
            status |= POINT_NEAR_SINGULAR
        if status & (POINT_UNREACHABLE | POINT_NOT_CONVERGED):
            reports.append(TargetReport(number, t.file, t.line, t.name, t.motion, w, ft.deflection,
                                        np.zeros(3), float("nan"), status, q_nom, q_nom, psi))
            continue
        c_nom, c_cmd = eng.configuration(q_nom), eng.configuration(ft.q)
        if c_nom is not None and fmt.config_key(c_nom) != fmt.config_key(c_cmd):
            status |= POINT_CONFIG_CHANGE
            if not o.allow_config_change:
                raise FilterError(f"{where}: target {t.name}: the compensation changes the arm "
                                  f"configuration ({fmt.key_text(fmt.config_key(c_nom))} -> "
                                  f"{fmt.key_text(fmt.config_key(c_cmd))}); move the target "
                                  "away from the singularity or choose another configuration")
        if key in done:
            if not np.allclose(done[key][0], w, atol=1e-9) or psi:
                raise FilterError(f"{where}: target {t.name} is used by several motions with "
                                  "different wrenches or tool rotations; give each motion its "
                                  "own point")
            first = done[key][1]
            reports.append(TargetReport(number, t.file, t.line, t.name, t.motion, w, ft.deflection,
                                        first.correction, first.residual, status, q_nom, ft.q,
                                        psi))
            continue
        if not np.any(w) and not psi:
            # no load and no rotation: nothing to compensate, the numbers stay as written
            reports.append(TargetReport(number, t.file, t.line, t.name, t.motion, w, ft.deflection,
                                        np.zeros(3), 0.0, status, q_nom, ft.q, psi))
            done[key] = (w, reports[-1])
            continue
        new_values = (list(o.joint_map.to_vendor(ft.q)) if t.joint
                      else fmt.values_of(ft.pose, t))
        texts = fmt.format_values(t, new_values, o.min_decimals)
        for (f, a, b), s in zip(t.spans, texts):
            reps.append((f, a, b, s))
        if c_cmd is not None and t.config is not None:
            reps.extend(fmt.config_replacements(t, c_cmd))
        # Predicted error of the program as written: the solver's residual (converged: below
        # 1e-12 m) plus what rounding the written digits moved the target off the exact one.
        written = fmt.parse_values(t, texts)
        pose_w = (eng.tcp_of_joints(o.joint_map.from_vendor(written), t) if t.joint
                  else fmt.pose_of(t, written))
        residual = float(np.linalg.norm(pose_w[:3, 3] - ft.pose[:3, 3]))
        reports.append(TargetReport(number, t.file, t.line, t.name, t.motion, w, ft.deflection,
                                    pose_w[:3, 3] - pose_ref[:3, 3], residual, status, q_nom,
                                    ft.q, psi))
        done[key] = (w, reports[-1])
    for r, p in zip(reports, plan):
        r.deflection_unrotated = p[5] if math.isfinite(p[5]) else float(
            np.linalg.norm(r.deflection[:3]))
    return FilterResult(program, program.rewrite(reps), reports)


def _rotate_paths(plan: list, eng: "_Engine", fmt, o: FilterOptions) -> None:
    """Stiffness-aware rotation about the tool axis of every run of consecutive Cartesian
    process targets (one path), in place (orient.py)."""
    from .orient import optimise_tool_rotation, rotate_about_tool_axis

    runs, cur = [], []
    for i, (t, pose, q, w, *_) in enumerate(plan):
        ok = t.process and not t.joint and q is not None
        if ok and cur and (plan[cur[-1]][0].base is not t.base or plan[cur[-1]][0].tool is not t.tool):
            runs.append(cur)
            cur = []
        if ok:
            cur.append(i)
        elif cur:
            runs.append(cur)
            cur = []
    if cur:
        runs.append(cur)
    key = None
    if eng.geometry is not None:
        key = lambda q: fmt.config_key(eng.configuration(q))
    for run in runs:
        t0 = plan[run[0]][0]
        # the process wrench does not turn with the tool; the weight of an off-axis tool does
        wrench_at = lambda k, pose, run=run: plan[run[k]][6] + _weight_wrench(
            plan[run[k]][0], pose, plan[run[k]][7])
        rot = optimise_tool_rotation(
            eng.model, [plan[i][1] for i in run], wrench_at, t0.base, t0.tool,
            plan[run[0]][2], limit_deg=o.tool_rotation_limit_deg,
            resolution_deg=o.tool_rotation_resolution_deg,
            max_step_deg=o.tool_rotation_max_step_deg, key=key, near_singular=eng.near_singular)
        for i, psi, q, d0 in zip(run, rot.psi, rot.q, rot.nominal):
            plan[i][1] = rotate_about_tool_axis(plan[i][1], float(psi))
            plan[i][3] = plan[i][6] + _weight_wrench(plan[i][0], plan[i][1], plan[i][7])
            plan[i][2] = q
            plan[i][4] = float(psi)
            plan[i][5] = float(d0)
