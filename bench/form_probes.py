"""Make scenarios of the library's effect classes in functional forms the development data do
not have, from a scenario directory's controls.

The development scenarios hold one form per class (coupling of joints 2 and 3, hardening of
joints 2 and 3, a force-frame error fixed in the base frame, drift with an unloaded pass before
the loaded one, ...). A diagnosis is judged on other forms of the same classes. This script adds
such forms to the displacements (or the force readings) of the control scenarios (type `none`)
of a directory laid out as bench/diagnosis_score.py reads it, so that noise and base compliance
stay the independent simulator's, and writes a directory the scoring harness reads (expected
verdict: `missing_effect` naming the class):

  coupling<j><k>   compliance coupling of joints j and k (coupling45: a coupled wrist gear
                   train; coupling13, coupling24: joints that are not neighbours, as in a
                   tendon-driven arm): d += c (J_j tau_k + J_k tau_j)
  cubic23          joints 2 and 3 hardening or softening with the cube of the load torque,
                   dtheta_j += -/+ w_j tau_j^3 / T^2 (no preload)            -> nonlinear_joint
  kink3            joint 3 stiffer in one direction than in the other, dtheta_3 += c max(tau_3, 0)
                   (a kinked, asymmetric torque-torsion curve)              -> nonlinear_joint
  force_flange     a force sensor on the flange turned by 3-8 deg about a random axis with
                   per-axis gains off by 2-5 %: the file states A F, the arm felt F (the
                   development data's frame error is fixed in the base frame) -> force_frame
  force_crosstalk  a force sensor on the flange with cross-axis sensitivity: the file states
                   (I + R X R^T) F, the arm felt F, X symmetric with a zero diagonal (8-12 %)
                                                                             -> force_frame
  force_crosstalk_base  the same reading error fixed in the base frame (a force plate under a
                   fixture): the file states (I + X) F                      -> force_frame
  tracker          the measured displacements rotated about a random axis   -> tracker_frame
  drift_settle     the tracker settling exponentially (time constant 0.5-1.5 sessions), the
                   unloaded pass first                                       -> drift
  drift_loaded_first   the same settling, the loaded pass first
  drift_reversed   a warm-up with a quadratic part, the loaded pass in reverse order
  drift_interleaved    each pose's two readings one after the other, a settling drift
  drift_timed      the tracker settling over the clock (time constant 10-30 min), readings at
                   irregular times with a pause of 10-20 min in the loaded pass, the loaded
                   reading's time written in a `t_s` column                  -> drift
  link_upper, link_fore, link_column, link_wrist   a spring inside the upper arm, the
                   forearm, the column (link 1) or the wrist (link 4) at a random point along
                   it, bending and twisting about the link frame's axes (the library's
                   springs sit at the link's root)                          -> link
  offset_meas      the measured point (SMR) alone off the robot file's along a random flange
                   direction: it moves with the flange's turn, d += (J_w C J_v^T F) x R r
  offset_load      the load point alone off the file's: the moment (R r) x F turns the arm,
                   d += J_v C J_w^T ((R r) x F) (C the control's joint compliances; the size
                   sets |r|, 6-11 cm at the default)                        -> point_offset
  compensator_lever    joint 2's compensator spring acting through a lever: its tangent
                   stiffness from the geometry (up to half the joint's), not a few harmonics
                   of q2                                                     -> gravity_compensator
  kinkg23, cubicg23, softzone23   joints 2 and 3 with a kink at the torque reversal, a cubic
                   law or a soft zone (knee 5-30 N*m) of the total torque, gravity preload
                   included                                                 -> nonlinear_joint
  backlash3, backlash25   lost motion of joint 3, or of joints 2 and 5     -> backlash
  backlash1        lost motion of joint 1, which gravity does not preload: unloaded it rests
                   anywhere in its gap (uniform), the load pushes it to the gap's side
                                                                             -> backlash
  k1+k2            two of the above at once (expected: both named), e.g. coupling24+drift_settle;
                   beside a point offset the other form is seen at the moved points

Usage:
  .venv/bin/python bench/form_probes.py --data DIR --out /tmp/forms --seeds 0-9
  .venv/bin/python bench/diagnosis_score.py --data /tmp/forms --sets base,sigma --noise given

Size: the part of the effect that five joint compliances cannot take up is set to `--size` um
RMS per axis on the calibration rows (default 40, about 1.3 times the development data's noise;
the development data's classes leave 5-20 % of the signal, 15-60 um), except force_flange and
force_crosstalk(_base), whose angles, gains and cross-talk are drawn, and a coupling that
would need |c_jk| above 0.8 sqrt(c_j c_k) of the control's fitted compliances (not positive
definite), which is held there (smaller).
The laws of the total torque use gravity torques of this script's own modified-DH chain with
every link's mass and centre of mass drawn 30 % off the robot file's, as a user's file is.
`true_class_refit_valid_um` is the joint compliances and the generating form (its shape fixed, its amplitudes free) refitted on calib.csv by least squares,
scored on valid.csv: what a right model can reach, the drift's law restarted in the validation
session. Needs the `stiff` Python package and numpy.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import sys

import numpy as np

from outside_probes import (controls, load_torques, prepare, probe_arguments, rotation,
                            write_index, write_scenario)

KINDS = {
    "coupling45": "coupling", "coupling35": "coupling", "coupling13": "coupling",
    "coupling24": "coupling", "cubic23": "nonlinear_joint", "kink3": "nonlinear_joint",
    "force_flange": "force_frame", "force_crosstalk": "force_frame",
    "force_crosstalk_base": "force_frame", "tracker": "tracker_frame", "drift_settle": "drift",
    "drift_loaded_first": "drift", "drift_reversed": "drift", "drift_interleaved": "drift",
    "drift_timed": "drift",
    "kinkg23": "nonlinear_joint", "cubicg23": "nonlinear_joint", "softzone23": "nonlinear_joint",
    "backlash3": "backlash", "backlash25": "backlash", "backlash1": "backlash", "link_upper": "link",
    "link_fore": "link", "link_column": "link", "link_wrist": "link",
    "compensator_lever": "gravity_compensator", "offset_meas": "point_offset",
    "offset_load": "point_offset",
}
# Kinds whose law acts on the total torque, gravity preload included (the masses drawn 30 % off
# the robot file's, as a user's file is).
PRELOADED = ("kinkg23", "cubicg23", "softzone23", "backlash3", "backlash25")
DESCRIPTION = {
    "cubic23": "joints 2 and 3 hardening or softening with the cube of the load torque",
    "kink3": "joint 3 stiffer in one load direction (a kinked torque-torsion curve)",
    "force_flange": "force-sensor frame error on the flange: rotation and per-axis gains",
    "force_crosstalk": "cross-axis sensitivity of a flange force sensor",
    "force_crosstalk_base": "cross-axis sensitivity of a force reading fixed in the base frame",
    "tracker": "laser-tracker frame misregistration about a random axis",
    "drift_settle": "tracker settling exponentially, the unloaded pass first",
    "drift_loaded_first": "tracker settling exponentially, the loaded pass first",
    "drift_reversed": "warm-up with a quadratic part, the loaded pass in reverse order",
    "drift_interleaved": "settling drift, the two readings of each pose one after the other",
    "drift_timed": "tracker settling over the clock, readings at irregular times with a pause, "
                   "the loaded reading's time in a t_s column",
    "kinkg23": "joints 2 and 3 stiffer in one direction of the total torque (a kink at the "
               "torque reversal, gravity preload; masses off the robot file's)",
    "cubicg23": "joints 2 and 3 hardening or softening with the cube of the total torque "
                "(gravity preload; masses off the robot file's)",
    "softzone23": "joints 2 and 3 with a soft zone about zero total torque, knee 5-30 N*m "
                  "(gravity preload; masses off the robot file's)",
    "backlash3": "lost motion of joint 3 under gravity preload (masses off the robot file's)",
    "backlash1": "lost motion of joint 1 without gravity preload (its unloaded rest anywhere in "
                 "the gap)",
    "backlash25": "lost motion of joints 2 and 5 under gravity preload (masses off the robot "
                  "file's)",
    "link_upper": "a spring inside the upper arm at a random point along it, bending and "
                  "twisting about the link frame's axes",
    "link_fore": "a spring inside the forearm at a random point along it, bending and twisting "
                 "about the link frame's axes",
    "link_column": "a spring inside the column (link 1) at a random point along it, bending and "
                   "twisting about the link frame's axes",
    "link_wrist": "a spring inside the wrist (link 4) at a random point along it, bending and "
                  "twisting about the link frame's axes",
    "offset_meas": "the measured point (SMR) alone off the robot file's along a random flange "
                   "direction, the length set by the size (the load point where the file "
                   "puts it)",
    "offset_load": "the load point alone off the robot file's along a random flange direction, "
                   "the length set by the size (the measured point where the file puts it)",
    "compensator_lever": "a compensator spring on joint 2 acting through a lever (its tangent "
                         "stiffness from the spring's geometry, not a few harmonics of q2)",
}
T_REF = 100.0  # N*m, the torque that scales the cubic law
GRAVITY = np.array([0.0, 0.0, -9.81])


def symmetric_offdiagonal(rng, low, high):
    """A symmetric 3 x 3 matrix with a zero diagonal, its three entries of sizes in [low, high]
    and random signs."""
    v = rng.uniform(low, high, 3) * rng.choice([-1.0, 1.0], 3)
    return np.array([[0, v[0], v[1]], [v[0], 0, v[2]], [v[1], v[2], 0]])


def sensor_readings(robot, arrays, a, flange):
    """Per file (no displacement added, the force the sensor reports A F, no regressor): a
    reading error A in the sensor's frame on the flange (R A R^T F) or fixed in the base."""
    out = {}
    for fn, (q, f, n) in arrays.items():
        rot = robot.tool_pose(q)[:, :3, :3] if flange else np.broadcast_to(np.eye(3), (n, 3, 3))
        written = np.einsum("nij,jk,nlk,nl->ni", rot, a, rot, f)
        out[fn] = (np.zeros_like(f), written, np.zeros((3 * n, 0)))
    return out


def read_dh_robot(path):
    """(the DH chain: convention and rows (alpha, a, d, theta offset) [rad, m]; masses [kg] and
    centres of mass [m] of links 1..n, then the tool's) from a robot file whose joints are
    one-line flow mappings, as the YAML files of examples/robots are (this script's own reading,
    independent of stiff's)."""
    rows, masses, coms = [], [], []
    tool = (0.0, np.zeros(3))
    with open(path) as f:
        text = f.read()
    conv = re.search(r"^convention:\s*(modified_dh|standard_dh)\s*$", text, re.M)
    units = re.search(r"^units:\s*\{length:\s*(mm|m),\s*angle:\s*(deg|rad)\}", text, re.M)
    if not conv or not units:
        raise SystemExit(f"form_probes: {path}: needs a DH convention and units (a YAML robot)")
    length = 1e-3 if units.group(1) == "mm" else 1.0
    angle = np.pi / 180 if units.group(2) == "deg" else 1.0
    for line in text.splitlines():
        m = re.match(r"\s*(- |tool: )(\{.*\})\s*(#.*)?$", line)
        if not m:
            continue
        entry = json.loads(re.sub(r"(\w+):", r'"\1":', m.group(2)))
        com = np.array(entry.get("com", [0, 0, 0]), float) * length
        if m.group(1) == "tool: ":
            tool = (float(entry.get("mass", 0)), com)
            continue
        rows.append((entry["alpha"] * angle, entry["a"] * length, entry["d"] * length,
                     entry.get("theta_offset", 0.0) * angle))
        masses.append(float(entry.get("mass", 0)))
        coms.append(com)
    chain = {"standard": conv.group(1) == "standard_dh", "rows": rows}
    return chain, masses + [tool[0]], coms + [tool[1]]


def chain_frames(chain, q_row):
    """(the frames 1..n, 4 x 4 in the base frame, frame n the flange; each joint's axis as
    (origin, direction)) at one row's joint angles. Modified DH: T = RotX(alpha) TransX(a)
    RotZ(q) TransZ(d), joint i turns about frame i's z. Standard DH: T = RotZ(q) TransZ(d)
    TransX(a) RotX(alpha), joint i turns about frame i-1's z."""
    t, frames, axes = np.eye(4), [], []
    for j, (alpha, a, d, offset) in enumerate(chain["rows"]):
        ca, sa = np.cos(alpha), np.sin(alpha)
        cq, sq = np.cos(q_row[j] + offset), np.sin(q_row[j] + offset)
        if chain["standard"]:
            axes.append((t[:3, 3].copy(), t[:3, 2].copy()))
            t = t @ np.array([[cq, -sq * ca, sq * sa, a * cq], [sq, cq * ca, -cq * sa, a * sq],
                              [0, sa, ca, d], [0, 0, 0, 1]])
        else:
            t = t @ np.array([[cq, -sq, 0, a], [sq * ca, cq * ca, -sa, -sa * d],
                              [sq * sa, cq * sa, ca, ca * d], [0, 0, 0, 1]])
            axes.append((t[:3, 3].copy(), t[:3, 2].copy()))
        frames.append(t)
    return frames, axes


def gravity_torques(chain, q, masses, coms):
    """(N, n): the torque the links' and the tool's weight put on each joint (the same sign as
    J^T F)."""
    n_rows, n = q.shape
    out = np.zeros((n_rows, n))
    for r in range(n_rows):
        frames, axes = chain_frames(chain, q[r])
        weights = [(t[:3, :3] @ c + t[:3, 3], m)
                   for t, c, m in zip(frames + [frames[-1]], coms, masses)]  # the tool last
        for j, (origin, axis) in enumerate(axes):
            for p, m in weights[j:]:
                out[r, j] += np.cross(axis, p - origin) @ (m * GRAVITY)
    return out


def flange_arms(robot, q, vectors):
    """(K, N, 3): each of the K vectors [m, flange frame] in the base frame at each row's pose."""
    return np.einsum("nij,kj->kni", robot.tool_pose(q)[:, :3, :3], np.asarray(vectors))


def link_spring(chain, q, f, link, along, c_rot, robot=None, shift=None):
    """(N, 3): the measured point's (the flange origin's) displacement from a spring inside
    link `link` (0-based frame index), at the fraction `along` of the way to the next joint's
    origin: the rest of the arm turns by c_rot (3 x 3 in the link's own frame) times the
    moment about the spring. `shift` (with `robot`, whose tool frame turns the offsets): the
    measured and load points' offsets (r_meas, r_load) from the flange origin [m]."""
    if chain["standard"]:
        raise SystemExit("form_probes: link springs need a modified-DH robot (its frame i sits "
                         "at link i's root)")
    offsets = np.zeros((2, len(q), 3))
    if shift is not None:
        offsets = flange_arms(robot, q, shift)
    out = np.zeros((len(q), 3))
    for r in range(len(q)):
        frames, _ = chain_frames(chain, q[r])
        rot = frames[link][:3, :3]
        o = (1 - along) * frames[link][:3, 3] + along * frames[link + 1][:3, 3]
        lever = frames[-1][:3, 3] - o
        turn = rot @ c_rot @ rot.T @ np.cross(lever + offsets[1, r], f[r])
        out[r] = np.cross(turn, lever + offsets[0, r])
    return out


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def rodrigues(axis_angle):
    a = np.linalg.norm(axis_angle)
    k = skew(axis_angle / a) if a > 0 else np.zeros((3, 3))
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def joint_columns(robot, q, f):
    """(3N, n): each joint's deflection per unit compliance under the row's force."""
    jv, tau = load_torques(robot, q, f)
    return (jv * tau[:, None, :]).reshape(-1, jv.shape[2])


def shifted_torques(robot, q, f, shift):
    """(the linear Jacobians N x 3 x n at the measured point, the joint torques N x n of the
    forces f applied at the load point), the two points moved by shift = (r_meas, r_load)
    [m, flange frame] from where the robot file puts them (None: where it puts them). A
    point R r off the flange's moves by v - (R r) x w."""
    if shift is None:
        return load_torques(robot, q, f)
    jac = robot.jacobian(q)
    jv, jw = jac[:, :3, :], jac[:, 3:, :]
    meas, load = (jv - np.cross(arm[:, :, None], jw, axis=1)
                  for arm in flange_arms(robot, q, shift))
    return meas, np.einsum("nij,ni->nj", load, f)


def drift_course(kind, rng):
    """(the drift's course per row of a session of n rows as a function of n, its direction,
    params)."""
    amp = rotation(rng)[:, 0]  # direction; the size sets the scale
    tau = rng.uniform(0.5, 1.5)  # settling time in sessions

    def settle(t, n):
        return 1.0 - np.exp(-t / (tau * n))

    def warm(t, n):
        return t / n + 0.5 * (t / n) ** 2

    def course(n):
        i = np.arange(n, dtype=float)
        if kind == "drift_settle":
            s = settle(n + i, 2 * n) - settle(i, 2 * n)
        elif kind == "drift_loaded_first":
            s = settle(i, 2 * n) - settle(n + i, 2 * n)
        elif kind == "drift_reversed":
            s = warm(2 * n - 1 - i, 2 * n) - warm(i, 2 * n)
        else:  # interleaved
            s = settle(2 * i + 1, 2 * n) - settle(2 * i, 2 * n)
        return s

    return course, amp, {"direction": amp.tolist(), "time_constant_sessions": tau}


def make_probe(kind, rng, robot, arrays, dh_robot, compliance, shift=None):
    """Per file: (displacement added [m] at unit scale, forces written or None, extra columns of
    the generating form for the reachable refit (3N x m) at unit scale), and the parameters.
    The caller scales the added displacement; forces and rotations are final. `shift`: the
    measured and load points' offsets (r_meas, r_load) of another form of the same arm (an
    SMR or load point off the file's sees this form's deflection there too), or None."""
    m = re.fullmatch(r"coupling([1-9])([1-9])", kind)
    out, params = {}, {}
    if m:
        j, k = int(m.group(1)) - 1, int(m.group(2)) - 1
        for fn, (q, f, n) in arrays.items():
            jv, tau = shifted_torques(robot, q, f, shift)
            d = jv[:, :, j] * tau[:, k, None] + jv[:, :, k] * tau[:, j, None]
            out[fn] = (d, None, d.reshape(-1, 1))
        params = {"joints": [j + 1, k + 1]}
    elif kind == "cubic23":
        w = rng.uniform(0.5, 1.0, 2) * rng.choice([-1.0, 1.0])
        for fn, (q, f, n) in arrays.items():
            jv, tau = shifted_torques(robot, q, f, shift)
            cols = [jv[:, :, j] * (tau[:, j] ** 3 / T_REF**2)[:, None] for j in (1, 2)]
            out[fn] = (w[0] * cols[0] + w[1] * cols[1], None,
                       np.stack([c.reshape(-1) for c in cols], axis=1))
        params = {"weights_j2_j3": w.tolist(), "T_Nm": T_REF,
                  "law": "hardening" if w[0] < 0 else "softening"}
    elif kind == "kink3":
        sign = rng.choice([-1.0, 1.0])
        for fn, (q, f, n) in arrays.items():
            jv, tau = shifted_torques(robot, q, f, shift)
            d = jv[:, :, 2] * np.maximum(sign * tau[:, 2], 0.0)[:, None]
            out[fn] = (d, None, d.reshape(-1, 1))
        params = {"softer_direction": sign}
    elif kind in PRELOADED:
        joints = {"backlash3": (2,), "backlash25": (1, 4)}.get(kind, (1, 2))
        w = rng.uniform(0.5, 1.0, len(joints))
        knee = rng.uniform(5.0, 30.0)
        sign = rng.choice([-1.0, 1.0])
        laws = {
            "kinkg23": np.abs,
            "cubicg23": lambda t: sign * t**3 / T_REF**2,
            "softzone23": lambda t: knee * np.tanh(t / knee),
            "backlash3": lambda t: 0.5 * np.sign(t),
            "backlash25": lambda t: 0.5 * np.sign(t),
        }
        law = laws[kind]
        masses = [m * rng.uniform(0.7, 1.3) for m in dh_robot[1]]
        coms = [c * rng.uniform(0.7, 1.3, 3) for c in dh_robot[2]]
        for fn, (q, f, n) in arrays.items():
            jv, tau = shifted_torques(robot, q, f, shift)
            tau_g = gravity_torques(dh_robot[0], q, masses, coms)
            cols = [jv[:, :, j] * (law(tau_g[:, j] + tau[:, j]) - law(tau_g[:, j]))[:, None]
                    for j in joints]
            out[fn] = (sum(wk * c for wk, c in zip(w, cols)), None,
                       np.stack([c.reshape(-1) for c in cols], axis=1))
        params = {"joints": [j + 1 for j in joints], "weights": w.tolist(),
                  "masses_kg": masses, "coms_m": [c.tolist() for c in coms]}
        if kind == "cubicg23":
            params["law"] = "softening" if sign > 0 else "hardening"
        if kind == "softzone23":
            params["knee_Nm"] = knee
    elif kind == "backlash1":
        # Where the joint rests in its gap unloaded is where the last motion left it: uniform
        # over the gap, drawn per reading; the load takes it to the side its torque pushes to.
        # What a model can reach is the mean, b/2 sgn(tau); the rest is scatter.
        for fn, (q, f, n) in arrays.items():
            jv, tau = shifted_torques(robot, q, f, shift)
            rest = rng.uniform(-0.5, 0.5, n)
            d = jv[:, :, 0] * (0.5 * np.sign(tau[:, 0]) - rest)[:, None]
            mean = jv[:, :, 0] * (0.5 * np.sign(tau[:, 0]))[:, None]
            out[fn] = (d, None, mean.reshape(-1, 1))
    elif kind.startswith("link_"):
        link = {"link_column": 0, "link_upper": 1, "link_fore": 2, "link_wrist": 3}[kind]
        along = rng.uniform(0.2, 0.8)
        # A casting bends and twists about the principal axes of its section (the link
        # frame's); its shear and stretch (1e8 N/m and stiffer) are below a micrometre at these
        # loads, so the spring turns and does not shift.
        c_rot = np.diag(rng.uniform(0.3, 1.0, 3)) * 1e-5  # rad/(N*m)
        for fn, (q, f, n) in arrays.items():
            d = link_spring(dh_robot[0], q, f, link, along, c_rot, robot, shift)
            out[fn] = (d, None, d.reshape(-1, 1))
        params = {"link_frame": link + 1, "along": along, "C_rot": c_rot.tolist()}
    elif kind == "compensator_lever":
        # A spring from a base point L from the axis to a point r out on the arm, at the angle
        # psi = q2 + phi: torque k r L sin(psi) (1 - l0 / l), l the spring's length; its
        # tangent stiffness in parallel with the joint's, up to half of it.
        big, small, l0 = 0.25, rng.uniform(0.06, 0.12), 0.1
        phi = rng.uniform(-np.pi, np.pi)

        def spring_stiffness(psi, h=1e-6):
            def torque(x):
                length = np.sqrt(small**2 + big**2 - 2 * small * big * np.cos(x))
                return small * big * np.sin(x) * (1 - l0 / length)
            return (torque(psi + h) - torque(psi - h)) / (2 * h)

        grid = spring_stiffness(np.linspace(-np.pi, np.pi, 721))
        kappa = 0.5 / np.abs(grid).max()
        for fn, (q, f, n) in arrays.items():
            jv, tau = shifted_torques(robot, q, f, shift)
            g = 1.0 / (1.0 + kappa * spring_stiffness(q[:, 1] + phi))
            d = jv[:, :, 1] * (tau[:, 1] * g)[:, None]
            out[fn] = (d, None, d.reshape(-1, 1))
        params = {"lever_m": small, "anchor_m": big, "free_length_m": l0, "phase_rad": phi}
    elif kind in ("offset_meas", "offset_load"):
        # Through the joint compliances C the load turns the flange by J_w C J_v^T F: a
        # measured point off by r moves by that turn x R r more; a load point off by r adds the
        # moment (R r) x F, moving the point by J_v C J_w^T ((R r) x F). Both are linear in r:
        # three columns, one per flange axis.
        r = rotation(rng)[:, 0]  # direction; the size sets the length
        for fn, (q, f, n) in arrays.items():
            jac = robot.jacobian(q)
            jv, jw = jac[:, :3, :], jac[:, 3:, :]
            rot = robot.tool_pose(q)[:, :3, :3]
            if kind == "offset_meas":
                turn = np.einsum("nij,j,nkj,nk->ni", jw, compliance, jv, f)
                cols = [np.cross(turn, rot[:, :, k]) for k in range(3)]
            else:
                cols = [np.einsum("nij,j,nkj,nk->ni", jv, compliance, jw,
                                  np.cross(rot[:, :, k], f)) for k in range(3)]
            d = sum(r[k] * cols[k] for k in range(3))
            out[fn] = (d, None, np.stack([c.reshape(-1) for c in cols], axis=1))
        params = {"direction_flange": r.tolist()}
    elif kind == "force_flange":
        axis = rotation(rng)[:, 0] * np.deg2rad(rng.uniform(3, 8))
        gains = rng.uniform(0.02, 0.05, 3) * rng.choice([-1.0, 1.0], 3)
        a = rodrigues(axis) @ np.diag(1 + gains)
        out = sensor_readings(robot, arrays, a, True)
        params = {"rotation_rad": axis.tolist(), "gains": gains.tolist()}
    elif kind in ("force_crosstalk", "force_crosstalk_base"):
        x = symmetric_offdiagonal(rng, 0.08, 0.12)
        out = sensor_readings(robot, arrays, np.eye(3) + x, kind == "force_crosstalk")
        params = {"X": x.tolist(), "frame": "flange" if kind == "force_crosstalk" else "base"}
    elif kind == "tracker":
        axis = rotation(rng)[:, 0]
        params = {"axis": axis.tolist()}
        out = {fn: (None, None, None) for fn in arrays}  # rotation: done by the caller
    elif kind == "drift_timed":
        amp = rotation(rng)[:, 0]
        tau = rng.uniform(600.0, 1800.0)  # s
        params = {"direction": amp.tolist(), "time_constant_s": tau}
        for fn, (q, f, n) in arrays.items():
            # An unloaded pass over the poses, then the loaded pass, 5 s + an exponential wait
            # of mean 25 s between readings, and one pause of 10-20 min in the loaded pass.
            dt = 5.0 + rng.exponential(25.0, 2 * n)
            dt[n + rng.integers(n // 4, 3 * n // 4)] += rng.uniform(600.0, 1200.0)
            t = np.cumsum(dt) - dt[0]
            unloaded, loaded = t[:n], t[n:]
            s_ = np.exp(-unloaded / tau) - np.exp(-loaded / tau)
            out[fn] = (s_[:, None] * amp[None, :], None, np.kron(s_[:, None], np.eye(3)), loaded)
    elif kind.startswith("drift_"):
        course, amp, params = drift_course(kind, rng)
        for fn, (q, f, n) in arrays.items():
            s = course(n)
            out[fn] = (s[:, None] * amp[None, :], None, np.kron(s[:, None], np.eye(3)))
    else:
        raise ValueError(kind)
    return out, params


def add_form(kind, rng, robot, arrays, dh_robot, joint, compliance, size, state):
    """Adds one form to state (per file: y the displacements, flat; cols the regressors of the
    generating model, the joint compliances' first; forces the written forces or None); returns
    its parameters, None when it cannot be made visible."""
    probe, params = make_probe(kind, rng, robot, arrays, dh_robot, compliance, state["shift"])
    files = list(arrays)
    for fn in files:  # a form that writes the readings' times
        if probe[fn] is not None and len(probe[fn]) > 3:
            state["times"][fn] = probe[fn][3]
    y, cols = state["y"], state["cols"]
    if kind == "tracker":
        # The rotation's first-order shape a x d sets the angle for the size.
        axis = np.array(params["axis"])
        shape = (y["calib.csv"].reshape(-1, 3) @ skew(axis).T).reshape(-1)
        angle = size * 1e-6 / rms_left(joint["calib.csv"], shape)
        rot = rodrigues(axis * angle)
        for fn in files:
            n = len(arrays[fn][1])
            y[fn] = (y[fn].reshape(-1, 3) @ rot.T).reshape(-1)
            cols[fn] = (cols[fn].T.reshape(-1, n, 3) @ rot.T).reshape(cols[fn].shape[1], -1).T
        params["angle_deg"] = float(np.rad2deg(angle))
        return params
    if kind in ("force_flange", "force_crosstalk", "force_crosstalk_base"):
        # The arm felt the true force: the regressors stay the true ones.
        state["forces"] = {fn: probe[fn][1] for fn in files}
        return params
    left = rms_left(joint["calib.csv"], probe["calib.csv"][0].reshape(-1))
    if left < 1e-12:
        print(f"form_probes: {kind} is invisible to this robot's measured point (the joint "
              "compliances take it up whole)", file=sys.stderr)
        return None
    scale = size * 1e-6 / left
    if kind.startswith("coupling"):
        # A physical compliance matrix is positive definite: |c_jk| < sqrt(c_j c_k) (the
        # control's fitted compliances); rho at most 0.8, the effect smaller.
        j, k = params["joints"]
        cap = 0.8 * np.sqrt(compliance[j - 1] * compliance[k - 1])
        params["rho"] = min(scale, cap) / np.sqrt(compliance[j - 1] * compliance[k - 1])
        scale = min(scale, cap)
    for fn in files:
        y[fn] = y[fn] + probe[fn][0].reshape(-1) * scale
        cols[fn] = np.hstack([cols[fn], probe[fn][2]])
    params["scale"] = scale
    if kind in ("offset_meas", "offset_load"):
        r = np.array(params["direction_flange"]) * scale
        state["shift"] = (r, np.zeros(3)) if kind == "offset_meas" else (np.zeros(3), r)
    return params


def reachable(cols_c, y_c, cols_v, y_v):
    """RMS per component of y_v left by cols_v at the least-squares fit of cols_c to y_c."""
    x, *_ = np.linalg.lstsq(cols_c, y_c, rcond=None)
    return float(np.sqrt(np.mean((y_v - cols_v @ x) ** 2)))


def rms_left(cols, y):
    """RMS per component of y after least squares on cols."""
    return reachable(cols, y, cols, y)


def main() -> int:
    ap = probe_arguments(__doc__, KINDS, 40.0,
                         "RMS per axis the joint compliances leave of the effect [um]")
    ap.add_argument("--robot-file", default=os.path.join(
        os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples", "robots",
        "rokae.yaml"), help="the same robot's YAML file (a DH chain), for the gravity preload and the links")
    a = ap.parse_args()
    import stiff

    robot = stiff.Robot(a.robot)
    dh_robot = read_dh_robot(a.robot_file)
    kinds = a.kinds.split(",")
    def known(kind):
        parts = kind.split("+")
        return len(parts) <= 2 and len(set(parts)) == len(parts) and all(
            k in KINDS or re.fullmatch(r"coupling[1-9][1-9]", k) for k in parts)

    if not prepare(a.out, kinds, known, KINDS, "form_probes"):
        return 2
    out_index = []
    for s, seed, src, files, data, truth0 in controls(a.data, a.sets, a.seeds, robot):
        arrays = {fn: (d.q, d.force, len(d)) for fn, d in data.items()}
        meas = {fn: d.displacement.reshape(-1) for fn, d in data.items()}
        joint = {fn: joint_columns(robot, *arrays[fn][:2]) for fn in files}
        compliance = 1.0 / np.asarray(stiff.identify(robot, data["calib.csv"]).stiffness)
        for kind in kinds:
            # A pair "k1+k2" adds both forms, each drawn as it is alone: a point offset first
            # (the other form's deflection is then seen at the moved points, as on an arm), the
            # tracker's rotation last (it turns what the tracker reads, the other effect
            # included).
            parts = sorted(kind.split("+"),
                           key=lambda k: (k == "tracker") - k.startswith("offset_"))
            state = {"y": dict(meas), "cols": dict(joint), "forces": None, "times": {},
                     "shift": None}
            params = {}
            for part in parts:
                rng = np.random.default_rng([seed] + [ord(c) for c in part])
                p = add_form(part, rng, robot, arrays, dh_robot, joint, compliance, a.size,
                             state)
                if p is None:
                    shutil.rmtree(a.out, ignore_errors=True)  # nothing half written
                    return 2
                params[part] = p
            if len(parts) == 1:
                params = params[kind]
            y, cols, forces = state["y"], state["cols"], state["forces"]
            add = {fn: (y[fn] - meas[fn]).reshape(-1, 3) for fn in files}
            if forces is not None:
                # What five compliances reach on the written forces (the base model).
                wc = {fn: joint_columns(robot, arrays[fn][0], forces[fn]) for fn in files}
                base = reachable(wc["calib.csv"], y["calib.csv"], wc["valid.csv"], y["valid.csv"])
            else:
                base = reachable(joint["calib.csv"], y["calib.csv"], joint["valid.csv"],
                                 y["valid.csv"])
            refit = reachable(cols["calib.csv"], y["calib.csv"], cols["valid.csv"], y["valid.csv"])
            dst = os.path.join(a.out, s, f"{kind}_{seed:02d}")
            write_scenario(src, dst, files, add, forces, state["times"] or None)
            effects = [KINDS.get(k, "coupling") for k in kind.split("+")]
            what = " and ".join(DESCRIPTION.get(k) or
                                f"compliance coupling of joints {k[8]} and {k[9]}"
                                for k in kind.split("+"))
            truth = dict(truth0, type=kind, description=what,
                         expected={"verdict": "missing_effect", "effects": effects},
                         effect_parameters=params,
                         base_model_valid_um={"axis_um": 1e6 * base},
                         true_class_refit_valid_um={"axis_um": 1e6 * refit},
                         effect_rms_calib_um=float(1e6 * np.sqrt(np.mean(add["calib.csv"] ** 2))))
            with open(os.path.join(dst, "truth.json"), "w") as f:
                json.dump(truth, f, indent=1)
            out_index.append({"path": f"{s}/{kind}_{seed:02d}", "type": kind,
                              "expected": truth["expected"]})
    write_index(a.out, out_index, "form_probes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
