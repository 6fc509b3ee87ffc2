"""Peer implementation of the identification, as a researcher would write it with numpy/scipy.

Same models as libstiff (libstiff/src/model/effects/{joint,link,point_offset}.cpp), re-implemented
from the robot's modified DH table (vectorised forward kinematics over all measurements):

- joint:  d = sum_j c_j tau_j (z_j x (P - o_j)),  tau_j = (z_j x (L - o_j)) . F + z_j . M
- link:   virtual rotational springs at the roots of links 2 and 3 about the axes joint i+1
          cannot absorb (frame-2 x and y, frame-3 x on the ROKAE arm), the same rule as link.cpp:
          d += c_v (u x (P - o)) ((u x (L - o)) . F + u . M)
- point_offset: P = p6 + R6 r_m, L = p6 + R6 r_l (flange frame offsets, 6 parameters).

`fit_joint_linear` solves the linear joint model with numpy.linalg.lstsq (columns that are
identically zero, joint 6 with the point on its axis, are dropped, as libstiff does).
`fit_huber` solves any of the models with scipy.optimize.least_squares(loss='huber',
f_scale = 3 sigma, method='trf', bounds from the parameter specs, finite-difference Jacobian
'2-point' as scipy's default), started like libstiff: joint compliances from the linear
solution, link compliances at 1e-6, offsets at 0. scipy's Huber acts on every residual
component; libstiff's on the norm of each measurement's 3-vector (same scale).
"""
from __future__ import annotations

import math

import re

import numpy as np
from scipy.optimize import least_squares


def load_dh(path):
    """(alpha [rad], a [m], d [m]) arrays of a modified-DH robot YAML (mm/deg units)."""
    # (no YAML library in the environment: the robot files use one flow map per joint)
    text = open(path).read()
    assert re.search(r"^convention:\s*modified_dh", text, re.M)
    ls = 1e-3 if re.search(r"length:\s*mm", text) else 1.0
    an = math.pi / 180 if re.search(r"angle:\s*deg", text) else 1.0
    num = r"\s*(-?[0-9.eE+-]+)"
    rows = [(float(m[0]) * an, float(m[1]) * ls, float(m[2]) * ls) for m in
            re.findall(r"-\s*\{\s*alpha:" + num + r",\s*a:" + num + r",\s*d:" + num, text)]
    return tuple(np.array(x) for x in zip(*rows))


def chain(dh, q):
    """Frames of all joints for all poses: R (N, n, 3, 3), o (N, n, 3)."""
    alpha, a, d = dh
    q = np.atleast_2d(q)
    n_meas, n = q.shape
    R = np.empty((n_meas, n, 3, 3))
    o = np.empty((n_meas, n, 3))
    Rc = np.broadcast_to(np.eye(3), (n_meas, 3, 3)).copy()
    pc = np.zeros((n_meas, 3))
    for i in range(n):
        ca, sa = math.cos(alpha[i]), math.sin(alpha[i])
        rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
        ct, st = np.cos(q[:, i]), np.sin(q[:, i])
        rz = np.zeros((n_meas, 3, 3))
        rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = ct, -st, st, ct, 1.0
        # T = RotX(alpha) TransX(a) RotZ(theta) TransZ(d)
        pc = pc + Rc @ np.array([a[i], 0.0, 0.0])
        Rc = Rc @ rx @ rz
        pc = pc + Rc[:, :, 2] * d[i]
        R[:, i], o[:, i] = Rc, pc
    return R, o


class Problem:
    """Precomputed kinematics of a data set (done once per fit, counted in the peer's time)."""

    def __init__(self, dh, q, force, moment, disp, effects):
        self.R, self.o = chain(dh, q)
        self.z = self.R[:, :, :, 2]  # joint axes (N, n, 3)
        self.F, self.M, self.d = force, moment, disp
        self.n = q.shape[1]
        self.effects = effects
        # Link springs (link.cpp rule at q = 0): frame of joint `link`, axes x, y of that
        # frame unless collinear with joint link+1.
        R0, _ = chain(dh, np.zeros((1, self.n)))
        self.springs = []
        if "link" in effects:
            for link in (2, 3):
                i = link - 1
                r = R0[0, i]
                a_ = r.T @ R0[0, i, :, 2]
                nxt = r.T @ R0[0, i + 1, :, 2]
                u1 = np.array([1.0, 0, 0]) - a_[0] * a_
                if np.linalg.norm(u1) < 0.3:
                    u1 = np.array([0, 1.0, 0]) - a_[1] * a_
                u1 /= np.linalg.norm(u1)
                u2 = np.cross(a_, u1)
                u2 /= np.linalg.norm(u2)
                for u in (u1, u2):
                    if abs(u @ nxt) <= 0.95:
                        self.springs.append((i, u))
        self.p6 = self.o[:, -1]
        self.R6 = self.R[:, -1]

    def n_params(self):
        k = self.n
        if "link" in self.effects:
            k += len(self.springs)
        if "point_offset" in self.effects:
            k += 6
        return k

    def predict(self, theta):
        n = self.n
        c = theta[:n]
        k = n
        cv = []
        if "link" in self.effects:
            cv = theta[k:k + len(self.springs)]
            k += len(self.springs)
        rm = rl = np.zeros(3)
        if "point_offset" in self.effects:
            rm, rl = theta[k:k + 3], theta[k + 3:k + 6]
        P = self.p6 + self.R6 @ rm
        L = self.p6 + self.R6 @ rl
        lever_l = np.cross(self.z, L[:, None, :] - self.o)  # (N, n, 3)
        lever_p = np.cross(self.z, P[:, None, :] - self.o)
        tau = np.einsum("njk,nk->nj", lever_l, self.F) + np.einsum("njk,nk->nj", self.z, self.M)
        d = np.einsum("nj,njk->nk", c * tau, lever_p)
        for cval, (i, u_loc) in zip(cv, self.springs):
            u = self.R[:, i] @ u_loc
            o = self.o[:, i]
            t = np.einsum("nk,nk->n", np.cross(u, L - o), self.F) + np.einsum("nk,nk->n", u, self.M)
            d = d + (cval * t)[:, None] * np.cross(u, P - o)
        return d

    def joint_columns(self):
        """(3N, n) design matrix of the linear joint model at zero offsets."""
        P = self.p6
        lever = np.cross(self.z, P[:, None, :] - self.o)
        tau = np.einsum("njk,nk->nj", lever, self.F) + np.einsum("njk,nk->nj", self.z, self.M)
        return (lever * tau[:, :, None]).transpose(0, 2, 1).reshape(-1, self.n)


def fit_joint_linear(prob: Problem):
    """Least-squares joint compliances; unidentifiable (zero) columns held at 0."""
    A = prob.joint_columns()
    scale = np.linalg.norm(A, axis=0)
    keep = scale > 1e-9 * scale.max()
    c = np.zeros(prob.n)
    sol, *_ = np.linalg.lstsq(A[:, keep] / scale[keep], prob.d.reshape(-1), rcond=None)
    c[keep] = sol / scale[keep]
    return c


def fit_huber(prob: Problem, sigma_m: float):
    """Robust fit of the problem's effects with scipy.optimize.least_squares(loss='huber')."""
    c0 = fit_joint_linear(prob)
    theta0, lo, hi = [c0], [np.zeros(prob.n)], [np.full(prob.n, 1e-2)]
    if "link" in prob.effects:
        k = len(prob.springs)
        theta0.append(np.full(k, 1e-6))
        lo.append(np.zeros(k))
        hi.append(np.full(k, 1e-2))
    if "point_offset" in prob.effects:
        theta0.append(np.zeros(6))
        lo.append(np.full(6, -0.5))
        hi.append(np.full(6, 0.5))
    theta0, lo, hi = (np.concatenate(x) for x in (theta0, lo, hi))
    theta0 = np.clip(theta0, lo, hi)
    res = least_squares(lambda th: (prob.predict(th) - prob.d).reshape(-1), theta0,
                        bounds=(lo, hi), loss="huber", f_scale=3 * sigma_m, method="trf",
                        x_scale="jac", max_nfev=200 * theta0.size)
    return res.x, res
