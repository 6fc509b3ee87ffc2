"""Stiffness-aware tool orientation (docs/olp.md): milling leaves the rotation psi about the
tool axis free. For a path of targets under their process wrenches, choose psi_i per target
that minimises the predicted deflection of the TCP, subject to

- limits: |psi_i| <= limit;
- smoothness: |psi_i - psi_(i-1)| <= max_step (a bounded rate along the path);
- the arm: every rotated target reachable within the joint limits, in the nominal target's
  configuration (same shoulder, elbow, wrist and turns), outside the singularity margins;
- never worse: at every target the predicted deflection is not larger than at psi = 0.

The angles live on a grid (step `resolution`); dynamic programming over the grid finds the
sequence with the least sum of squared deflections among the admissible, smooth ones (plus a
small cost on each change and on the size of the rotation, which settle ties towards a smooth
and small rotation). psi = 0
everywhere is always admissible when the nominal path is, so a solution exists.
The process wrench is independent of psi (a rotationally symmetric cutter: the cutting force
follows the feed direction and the tool axis, not the spindle housing); the weight of a tool
whose centre of gravity is off the tool axis turns with it (pass wrenches as a function)."""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np

from ..compensate import POINT_NOT_CONVERGED, POINT_SINGULAR, POINT_UNREACHABLE
from .target import filter_target

__all__ = ["ToolRotation", "optimise_tool_rotation", "rotate_about_tool_axis"]


def rotate_about_tool_axis(pose: np.ndarray, psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    rz = np.eye(4)
    rz[:2, :2] = [[c, -s], [s, c]]
    return pose @ rz


@dataclass
class ToolRotation:
    psi: np.ndarray            # (N,) rotation about the tool axis [rad] per target
    deflection: np.ndarray     # (N,) predicted TCP deflection at psi [m]
    nominal: np.ndarray        # (N,) predicted TCP deflection at psi = 0 [m]
    q: np.ndarray              # (N, n) nominal joints of the rotated targets
    grid: np.ndarray           # candidate angles [rad]
    admissible: np.ndarray     # (N, len(grid)) bool


def optimise_tool_rotation(model, poses, wrenches, base=None, tool=None, q_seed=None, *,
                           limit_deg: float = 90.0, resolution_deg: float = 5.0,
                           max_step_deg: float = 10.0, key=None, near_singular=None,
                           ) -> ToolRotation:
    """poses: (N, 4, 4) TCP targets in the reference frame; wrenches: (N, 6) at the TCP in the
    reference frame, or wrenches(i, rotated_pose) -> (6,) when the wrench turns with the tool
    (the weight of an off-axis tool); q_seed: joints near the first target's nominal solution. key(q): the
    configuration that must not change (e.g. a format's configuration flags); near_singular(q):
    True inside the singularity margins. Both default to none."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
    n_pts = poses.shape[0]
    if callable(wrenches):
        wrench_at = wrenches
    else:
        w = np.asarray(wrenches, dtype=float).reshape(-1, 6)
        wrench_at = lambda i, pose: w[i]
    k = int(round(limit_deg / resolution_deg))
    grid = np.radians(resolution_deg) * np.arange(-k, k + 1)
    zero = k
    dof = model.robot.dof
    defl = np.full((n_pts, grid.size), np.inf)
    qs = np.zeros((n_pts, grid.size, dof))
    seed = q_seed
    bad = POINT_UNREACHABLE | POINT_SINGULAR | POINT_NOT_CONVERGED
    for i in range(n_pts):
        nom = filter_target(model, poses[i], seed, wrench_at(i, poses[i]), base, tool)
        if nom.status & bad:
            raise ValueError(f"target {i + 1}: the nominal orientation is not usable "
                             f"(status {nom.status}); fix the path first")
        q_nom = _nominal_q(model, poses[i], nom, seed, base, tool)
        seed = q_nom
        k0 = None if key is None else key(q_nom)
        for j, psi in enumerate(grid):
            if j == zero:
                defl[i, j], qs[i, j] = np.linalg.norm(nom.deflection[:3]), q_nom
                continue
            rotated = rotate_about_tool_axis(poses[i], psi)
            r = filter_target(model, rotated, q_nom, wrench_at(i, rotated), base, tool)
            if r.status & bad:
                continue
            q = _nominal_q(model, rotate_about_tool_axis(poses[i], psi), r, q_nom, base, tool)
            if key is not None and key(q) != k0:
                continue
            if near_singular is not None and near_singular(q):
                continue
            defl[i, j], qs[i, j] = np.linalg.norm(r.deflection[:3]), q
    admissible = defl <= defl[:, [zero]] * (1 + 1e-12)
    admissible &= np.isfinite(defl)
    # Dynamic programming: least sum of squares with |psi_i - psi_(i-1)| <= max_step. Among
    # equal deflections the smaller rotation wins (a 1e-6 relative pull towards psi = 0).
    reach = int(math.floor(max_step_deg / resolution_deg + 1e-9))
    pull = 1e-6 * float(np.mean(defl[:, zero] ** 2)) * grid ** 2
    # A change between targets costs a thousandth of a mean squared deflection per max_step^2:
    # it settles ties and tiny gains towards a smooth rotation.
    smooth = 1e-3 * float(np.mean(defl[:, zero] ** 2))
    cost = np.where(admissible[0], defl[0] ** 2 + pull, np.inf)
    back = np.zeros((n_pts, grid.size), dtype=int)
    for i in range(1, n_pts):
        new = np.full(grid.size, np.inf)
        for j in range(grid.size):
            if not admissible[i, j]:
                continue
            lo, hi = max(0, j - reach), min(grid.size, j + reach + 1)
            step = cost[lo:hi] + smooth * ((np.arange(lo, hi) - j) / max(reach, 1)) ** 2
            b = lo + int(np.argmin(step))
            new[j] = step[b - lo] + defl[i, j] ** 2 + pull[j]
            back[i, j] = b
        cost = new
    j = int(np.argmin(cost))
    path = [j]
    for i in range(n_pts - 1, 0, -1):
        j = back[i, j]
        path.append(j)
    path = np.array(path[::-1])
    idx = np.arange(n_pts)
    return ToolRotation(grid[path], defl[idx, path], defl[:, zero], qs[idx, path], grid,
                        admissible)


def _nominal_q(model, pose, res, seed, base, tool):
    """Unloaded joints of a target: filter_target with a zero wrench returns them."""
    r = filter_target(model, pose, res.q, None, base, tool)
    return r.q
