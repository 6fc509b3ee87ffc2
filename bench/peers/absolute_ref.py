"""Reference absolute calibration, written independently of libstiff with numpy/scipy only.

It is what stiff's geometric calibration is checked against on real laser-tracker data
(docs/real-data.md). The model, for a serial arm of revolute joints in standard DH:

- joint i: A_i = RotZ(q_i + theta_i + dtheta_i + dq_grav_i + dq_harm_i) TransZ(d_i + dd_i)
  TransX(a_i + da_i) RotX(alpha_i + dalpha_i) RotY(beta_i); beta_i (Hayati 1983) only where
  the axes of joints i and i+1 are nominally parallel (alpha_i = 0 or pi), where the DH normal
  is not defined and dd_i alone would not stay continuous;
- the registration of each session (one tracker placement): p_instrument = R_s p_base + t_s,
  six parameters per session, a small rotation vector and a translation about the initial
  estimate (Kabsch on the nominal model);
- the tool: the target point in the flange frame (3), and with 6-D data the probe frame's
  rotation (3 more);
- optionally transmission errors periodic in the joint angle: dq_harm_i = s1 sin q_i +
  c1 cos q_i + s2 sin 2q_i + c2 cos 2q_i (first and second harmonic), per joint;
- optionally gravity compliance, lumped: dq_grav_i = sum_k k_ik phi_ik(q), with
  phi_ik = z_{i-1} . ((o_k - o_{i-1}) x g_hat) the gravity-torque lever of a point mass at the
  origin o_k of each later frame (and at the target), computed once from the nominal geometry.
  The unknowns k_ik (compliance times lumped mass times g, rad/m) are linear; no mass model.

What the data can identify is chosen by column-pivoted QR (Businger-Golub, ties within 1e-6 taken
in column order: see pivoted_qr) of the finite-difference Jacobian at the start point with
unit-norm columns: a parameter whose pivot |R_kk| falls below `tol` times the first is held at
its nominal value and named. The remaining parameters are fitted by
scipy.optimize.least_squares with its finite-difference Jacobian ('2-point'). Residuals: position in m, orientation (rotation vector of
R_model^T R_measured) in rad times `orientation_weight_m` (default 1 m: 1 mrad weighs 1 mm).

Reads the absolute measurement format (docs/formats.md): id, session, q*_rad|_deg,
px/py/pz_m|_mm|_um, optional a/b/c_rad|_deg with `# euler: xyz|zyx`.

    python bench/peers/absolute_ref.py ur5  [--data-dir examples/real] [--json out.json]
    python bench/peers/absolute_ref.py ur10 [--data-dir examples/real] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[2]

# ----------------------------------------------------------------------------- robots

# UR5 standard DH (Universal Robots' table, third series; the same geometry as
# examples/robots/ur5.urdf): alpha [rad], a [m], d [m], theta offset [rad].
UR5_DH = (np.array([math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0]),
          np.array([0, -0.425, -0.39225, 0, 0, 0]),
          np.array([0.089159, 0, 0, 0.10915, 0.09465, 0.0823]),
          np.zeros(6))


def load_standard_dh(path):
    """(alpha, a, d, theta_offset) in rad and m from a standard-DH robot YAML."""
    # The robot files use one flow map per joint; no YAML library is needed for them.
    text = Path(path).read_text()
    if not re.search(r"^convention:\s*standard_dh", text, re.M):
        raise ValueError(f"{path}: not a standard_dh robot file")
    ls = 1e-3 if re.search(r"length:\s*mm", text) else 1.0
    an = math.pi / 180 if re.search(r"angle:\s*deg", text) else 1.0
    rows = []
    for m in re.finditer(r"^\s*-\s*\{(.*)\}\s*$", text, re.M):
        kv = dict(re.findall(r"(\w+):\s*(-?[0-9.eE+-]+)", m.group(1)))
        rows.append((float(kv["alpha"]) * an, float(kv["a"]) * ls, float(kv["d"]) * ls,
                     float(kv.get("theta_offset", 0)) * an))
    return tuple(np.array(c) for c in zip(*rows))


def robot_dh(name):
    if name == "ur5":
        return UR5_DH
    return load_standard_dh(ROOT / "examples" / "robots" / f"{name}.yaml")


# ----------------------------------------------------------------------------- data

_LEN = {"m": 1.0, "mm": 1e-3, "um": 1e-6}
_ANG = {"rad": 1.0, "deg": math.pi / 180}


def read_absolute(path):
    """Absolute measurement CSV -> dict(ids, session, q [rad], p [m], R or None, meta)."""
    meta, rows, header = {}, [], None
    for line in Path(path).read_text(encoding="utf-8-sig").splitlines():
        if line.startswith("#"):
            m = re.match(r"#\s*([^:]+):\s*(.*)$", line)
            if m:
                meta[m.group(1).strip()] = m.group(2).strip()
            continue
        if not line.strip():
            continue
        f = [x.strip().strip('"') for x in line.split(",")]
        if header is None:
            header = f
        else:
            rows.append(f)
    col = {h: i for i, h in enumerate(header)}

    def get(name, units):
        for u, s in units.items():
            if f"{name}_{u}" in col:
                return np.array([float(r[col[f"{name}_{u}"]]) for r in rows]) * s
        return None

    q = []
    for j in range(1, 20):
        v = get(f"q{j}", _ANG)
        if v is None:
            break
        q.append(v)
    out = {"meta": meta, "q": np.stack(q, 1),
           "p": np.stack([get(k, _LEN) for k in ("px", "py", "pz")], 1),
           "ids": [r[col["id"]] for r in rows],
           "session": np.array([r[col["session"]] for r in rows])}
    eul = [get(k, _ANG) for k in "abc"]
    out["R"] = None
    if eul[0] is not None:
        seq = {"xyz": "XYZ", "zyx": "ZYX"}[meta["euler"]]  # intrinsic
        out["R"] = Rotation.from_euler(seq, np.stack(eul, 1)).as_matrix()
    return out


def subset(data, idx):
    out = dict(data)
    for k in ("q", "p", "session"):
        out[k] = data[k][idx]
    out["R"] = None if data["R"] is None else data["R"][idx]
    out["ids"] = [data["ids"][i] for i in idx]
    return out


# ----------------------------------------------------------------------------- kinematics

def _dh_batch(theta, d, a, alpha, beta):
    """Batch of RotZ(theta) TransZ(d) TransX(a) RotX(alpha) RotY(beta), shape (n, 4, 4)."""
    n = theta.shape[0]
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    cb, sb = math.cos(beta), math.sin(beta)
    T = np.zeros((n, 4, 4))
    # RotZ RotX
    Rzx = np.empty((n, 3, 3))
    Rzx[:, 0, 0], Rzx[:, 0, 1], Rzx[:, 0, 2] = ct, -st * ca, st * sa
    Rzx[:, 1, 0], Rzx[:, 1, 1], Rzx[:, 1, 2] = st, ct * ca, -ct * sa
    Rzx[:, 2, 0], Rzx[:, 2, 1], Rzx[:, 2, 2] = 0.0, sa, ca
    if beta == 0.0:
        T[:, :3, :3] = Rzx
    else:
        T[:, :3, :3] = Rzx @ np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    T[:, 0, 3], T[:, 1, 3], T[:, 2, 3] = a * ct, a * st, d
    T[:, 3, 3] = 1.0
    return T


def _skew_exp(w):
    return Rotation.from_rotvec(w).as_matrix()


class Model:
    """Parameter layout and forward model of the reference calibration."""

    def __init__(self, dh, sessions, six_d, gravity, hayati_tol=1e-6, harmonics=False):
        self.alpha, self.a, self.d, self.off = dh
        self.n = len(self.alpha)
        self.sessions = list(sessions)
        self.six_d, self.gravity, self.harmonics = six_d, gravity, harmonics
        names = []
        self.hayati = []
        for i in range(self.n):
            j = i + 1
            names += [f"theta{j}", f"d{j}", f"a{j}", f"alpha{j}"]
            # Parallel to the next joint's axis: Hayati's beta (the last joint has no next).
            if i < self.n - 1 and abs(math.sin(self.alpha[i])) < hayati_tol:
                names.append(f"beta{j}")
                self.hayati.append(i)
        for s in self.sessions:
            names += [f"reg[{s}].{k}" for k in ("wx", "wy", "wz", "tx", "ty", "tz")]
        names += ["tool.x", "tool.y", "tool.z"]
        if six_d:
            names += ["tool.wx", "tool.wy", "tool.wz"]
        self.grav_pairs = []
        if gravity:
            for i in range(self.n):
                for k in list(range(i + 1, self.n + 1)) + ["tcp"]:
                    if k == self.n:
                        continue  # the flange origin: kept through the target point
                    self.grav_pairs.append((i, k))
                    names.append(f"grav.j{i + 1}.{'tcp' if k == 'tcp' else 'o%d' % k}")
        if harmonics:
            for j in range(1, self.n + 1):
                names += [f"harm.j{j}.{k}" for k in ("s1", "c1", "s2", "c2")]
        self.names = names
        self.index = {nm: i for i, nm in enumerate(names)}
        # Initial (nominal) values that the parameters are deviations from.
        self.reg0 = {s: (np.eye(3), np.zeros(3)) for s in self.sessions}
        self.tool0 = np.zeros(3)
        self.toolR0 = np.eye(3)

    # -- forward model
    def chain(self, x, q, dq=None):
        """Flange frames (n, 4, 4) and the joint frames' origins/axes if asked."""
        idx = self.index
        T = np.broadcast_to(np.eye(4), (q.shape[0], 4, 4)).copy()
        frames = [T]
        for i in range(self.n):
            j = i + 1
            th = q[:, i] + self.off[i] + x[idx[f"theta{j}"]]
            if dq is not None:
                th = th + dq[:, i]
            beta = x[idx[f"beta{j}"]] if f"beta{j}" in idx else 0.0
            A = _dh_batch(th, self.d[i] + x[idx[f"d{j}"]], self.a[i] + x[idx[f"a{j}"]],
                          self.alpha[i] + x[idx[f"alpha{j}"]], beta)
            T = T @ A
            frames.append(T)
        return frames

    def tool(self, x):
        idx = self.index
        t = self.tool0 + np.array([x[idx["tool.x"]], x[idx["tool.y"]], x[idx["tool.z"]]])
        R = self.toolR0
        if self.six_d:
            R = R @ _skew_exp(np.array([x[idx["tool.wx"]], x[idx["tool.wy"]],
                                        x[idx["tool.wz"]]]))
        return t, R

    def registration(self, x, s):
        idx = self.index
        R0, t0 = self.reg0[s]
        w = np.array([x[idx[f"reg[{s}].w{c}"]] for c in "xyz"])
        t = np.array([x[idx[f"reg[{s}].t{c}"]] for c in "xyz"])
        return _skew_exp(w) @ R0, t0 + t

    def gravity_regressors(self, x, q):
        """phi[:, m] for each (joint, point) pair, from the geometry at x (nominal: x = 0)."""
        frames = self.chain(x, q)
        t, _ = self.tool(x)
        tcp = frames[-1][:, :3, :3] @ t + frames[-1][:, :3, 3]
        g = np.array([0.0, 0.0, -1.0])
        phi = np.empty((q.shape[0], len(self.grav_pairs)))
        for m, (i, k) in enumerate(self.grav_pairs):
            z, o = frames[i][:, :3, 2], frames[i][:, :3, 3]
            pk = tcp if k == "tcp" else frames[k][:, :3, 3]
            phi[:, m] = np.einsum("ij,ij->i", z, np.cross(pk - o, g))
        return phi

    def predict(self, x, data, phi=None):
        """Target position (n, 3) [m] and rotation (n, 3, 3) in the instrument frame."""
        q = data["q"]
        dq = None
        if self.gravity:
            k = np.array([x[self.index[f"grav.j{i + 1}.{'tcp' if kk == 'tcp' else 'o%d' % kk}"]]
                          for i, kk in self.grav_pairs])
            dq = np.zeros_like(q)
            contrib = phi * k
            for m, (i, _) in enumerate(self.grav_pairs):
                dq[:, i] += contrib[:, m]
        if self.harmonics:
            dq = np.zeros_like(q) if dq is None else dq
            for j in range(self.n):
                h = [x[self.index[f"harm.j{j + 1}.{k}"]] for k in ("s1", "c1", "s2", "c2")]
                qj = q[:, j]
                dq[:, j] += (h[0] * np.sin(qj) + h[1] * np.cos(qj) + h[2] * np.sin(2 * qj)
                             + h[3] * np.cos(2 * qj))
        F = self.chain(x, q, dq)[-1]
        t, Rt = self.tool(x)
        p = F[:, :3, :3] @ t + F[:, :3, 3]
        R = F[:, :3, :3] @ Rt
        out_p = np.empty_like(p)
        out_R = np.empty_like(R)
        for s in np.unique(data["session"]):
            m = data["session"] == s
            Rs, ts = self.registration(x, s)
            out_p[m] = p[m] @ Rs.T + ts
            out_R[m] = Rs @ R[m]
        return out_p, out_R


def rotation_error(Rm, Rp):
    """Rotation vectors of Rp^T Rm, (n, 3) [rad]."""
    return Rotation.from_matrix(np.einsum("nji,njk->nik", Rp, Rm)).as_rotvec()


# ----------------------------------------------------------------------------- calibration

class Calibration:
    def __init__(self, model, x, free, held, rank_info, phi_fn, stats):
        self.model, self.x, self.free, self.held = model, x, free, held
        self.rank_info, self.phi_fn, self.stats = rank_info, phi_fn, stats

    def predict(self, data):
        phi = self.phi_fn(data["q"]) if self.model.gravity else None
        return self.model.predict(self.x, data, phi)


def kabsch(P, Q):
    """R, t minimising |R P + t - Q|."""
    Pc, Qc = P.mean(0), Q.mean(0)
    U, _, Vt = np.linalg.svd((P - Pc).T @ (Q - Qc))
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, Qc - R @ Pc


def residuals(model, x, data, phi, w_o):
    p, R = model.predict(x, data, phi)
    r = [(p - data["p"]).ravel()]
    if model.six_d and data["R"] is not None:
        r.append(w_o * rotation_error(data["R"], R).ravel())
    return np.concatenate(r)


def fd_jacobian(f, x, h=1e-7):
    f0 = f(x)
    J = np.empty((f0.size, x.size))
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        J[:, k] = (f(x + e) - f(x - e)) / (2 * h)
    return J


def initialise(model, data):
    """Nominal start: registration per session by Kabsch on the flange, then the registration
    and target point by least squares with the nominal geometry; the probe rotation (6-D)
    by the chordal mean of R_flange^T R_reg^T R_measured."""
    x = np.zeros(len(model.names))
    F = model.chain(x, data["q"])[-1]
    for s in model.sessions:
        m = data["session"] == s
        model.reg0[s] = kabsch(F[m][:, :3, 3], data["p"][m])
    sub = [model.index[n] for n in model.names if n.startswith(("reg[", "tool.x", "tool.y",
                                                                  "tool.z"))]

    def f(y):
        xx = x.copy()
        xx[sub] = y
        p, _ = model.predict(xx, data, None if not model.gravity else
                             np.zeros((len(data["q"]), len(model.grav_pairs))))
        return (p - data["p"]).ravel()

    sol = least_squares(f, np.zeros(len(sub)), method="lm")
    x[sub] = sol.x
    # Fold the estimates into the nominal values so that the calibration starts at zero.
    for s in model.sessions:
        model.reg0[s] = model.registration(x, s)
    model.tool0 = model.tool(x)[0]
    x[:] = 0.0
    if model.six_d and data["R"] is not None:
        F = model.chain(x, data["q"])[-1]
        M = np.zeros((3, 3))
        for s in model.sessions:
            m = data["session"] == s
            Rs, _ = model.registration(x, s)
            M += np.einsum("nji,jk,nkl->il", F[m][:, :3, :3], Rs.T, data["R"][m])
        U, _, Vt = np.linalg.svd(M)
        model.toolR0 = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return x


def pivoted_qr(A, ties=1e-6):
    """Column-pivoted QR (Businger & Golub 1965) by modified Gram-Schmidt: the pivot order and
    |diag R|. Columns whose remaining norms agree within `ties` (relative) are taken in column
    order: exactly dependent columns (translations along parallel axes) then tie up to the
    finite-difference Jacobian's noise, which LAPACK's pivoting resolves by round-off, so that
    another BLAS kernel would hold another member of the same combination."""
    R = np.array(A, dtype=float)
    n = R.shape[1]
    order, diag = [], []
    rest = list(range(n))
    for _ in range(n):
        norms = np.linalg.norm(R[:, rest], axis=0)
        top = norms.max()
        k = rest[int(np.flatnonzero(norms >= top * (1 - ties))[0])]
        order.append(k)
        diag.append(top)
        rest.remove(k)
        if top > 0 and rest:
            q = R[:, k] / top
            R[:, rest] -= np.outer(q, q @ R[:, rest])
    return np.array(order), np.array(diag)


def calibrate(dh, data, *, gravity=False, tol=1e-3, w_o=1.0, harmonics=False):
    six_d = data["R"] is not None
    model = Model(dh, np.unique(data["session"]), six_d, gravity, harmonics=harmonics)
    x0 = initialise(model, data)
    phi_fn = (lambda q: model.gravity_regressors(np.zeros(len(model.names)), q))
    phi = phi_fn(data["q"]) if gravity else None
    t0 = time.process_time()  # CPU seconds: single-threaded, steady on a shared machine
    J = fd_jacobian(lambda x: residuals(model, x, data, phi, w_o), x0)
    norms = np.linalg.norm(J, axis=0)
    nz = norms > 0
    Js = J[:, nz] / norms[nz]
    piv, diag = pivoted_qr(Js)
    rank = int(np.sum(diag > tol * diag[0]))
    cols = np.flatnonzero(nz)
    free = np.sort(cols[piv[:rank]])
    held = [model.names[i] for i in range(len(model.names)) if i not in set(free)]

    def f(y):
        x = x0.copy()
        x[free] = y
        return residuals(model, x, data, phi, w_o)

    t1 = time.process_time()
    sol = least_squares(f, np.zeros(free.size), jac="2-point", method="trf", x_scale="jac")
    elapsed = time.process_time() - t0
    fit_seconds = time.process_time() - t1
    x = x0.copy()
    x[free] = sol.x
    r = f(sol.x)
    npos = 3 * len(data["q"])
    stats = {"rms_mm": float(np.sqrt(np.mean(r[:npos].reshape(-1, 3) ** 2 * 3)) * 1e3),
             "parameters": int(free.size), "held": held, "seconds": elapsed,
             "least_squares_seconds": fit_seconds,
             "nfev": int(sol.nfev)}
    return Calibration(model, x, free, held, diag / diag[0], phi_fn, stats)


def register_session(cal, data, w_o=1.0):
    """Refit only the registration of a new session (geometry, tool, gravity kept)."""
    model = cal.model
    s = data["session"][0]
    fake = Model((model.alpha, model.a, model.d, model.off), [s], model.six_d, model.gravity,
                 harmonics=model.harmonics)
    fake.tool0, fake.toolR0 = model.tool0, model.toolR0
    x = np.zeros(len(fake.names))
    for nm, i in fake.index.items():
        if not nm.startswith("reg["):
            x[i] = cal.x[model.index[nm]]
    phi = cal.phi_fn(data["q"]) if model.gravity else None
    # Start from Kabsch on the calibrated model's base-frame targets.
    fake.reg0[s] = (np.eye(3), np.zeros(3))
    pb, _ = fake.predict(x, data, phi)
    fake.reg0[s] = kabsch(pb, data["p"])
    sub = [fake.index[f"reg[{s}].{k}"] for k in ("wx", "wy", "wz", "tx", "ty", "tz")]

    def f(y):
        xx = x.copy()
        xx[sub] = y
        return residuals(fake, xx, data, phi, w_o)

    sol = least_squares(f, np.zeros(6), method="lm")
    x[sub] = sol.x
    return lambda d: fake.predict(x, d, cal.phi_fn(d["q"]) if model.gravity else None)


def errors(pred, data):
    p, R = pred
    e = np.linalg.norm(p - data["p"], axis=1) * 1e3
    out = {"mean_mm": float(e.mean()), "max_mm": float(e.max()),
           "rms_mm": float(np.sqrt(np.mean(e ** 2))), "n": int(e.size),
           "ci95_mean_mm": float(1.96 * e.std(ddof=1) / math.sqrt(e.size)) if e.size > 1 else None}
    if data["R"] is not None:
        a = np.degrees(np.linalg.norm(rotation_error(data["R"], R), axis=1))
        out.update({"mean_deg": float(a.mean()), "max_deg": float(a.max())})
    out["per_pose_mm"] = [round(float(v), 5) for v in e]
    return out


def nominal_stats(model, x, data):
    e = errors(model.predict(x, data), data)
    return {"rms_mm": e["rms_mm"], "parameters": sum(
        1 for n in model.names if n.startswith(("reg[", "tool."))), "held": [],
        "seconds": 0.0, "nfev": 0}


def uncalibrated(dh, data):
    """The nominal model with only the registration and target point (probe frame) fitted."""
    model = Model(dh, np.unique(data["session"]), data["R"] is not None, False)
    x = initialise(model, data)
    return model, x


# ----------------------------------------------------------------------------- studies

# Models compared: name -> (gravity compliance, joint harmonics).
MODEL_SET = {"geometry": (False, False), "geometry+gravity": (True, False),
             "geometry+harmonics": (False, True), "geometry+gravity+harmonics": (True, True)}
UR5_MODELS = ("geometry", "geometry+gravity", "geometry+harmonics", "geometry+gravity+harmonics")
UR10_MODELS = ("geometry", "geometry+gravity", "geometry+gravity+harmonics")


def study_ur5(data_dir, tol=1e-3, folds=5, seed=0):
    dh = robot_dh("ur5")
    grid = read_absolute(Path(data_dir) / "ur5" / "ur5_grid.csv")
    test = read_absolute(Path(data_dir) / "ur5" / "ur5_random.csv")
    res = {"dataset": "ur5-jacobi2025", "calibration_rows": len(grid["q"]),
           "validation_rows": len(test["q"])}
    model, x = uncalibrated(dh, grid)
    res["nominal"] = {"calibration": nominal_stats(model, x, grid),
                      "validation": errors(model.predict(x, test), test)}
    for name in UR5_MODELS:
        grav, harm = MODEL_SET[name]
        cal = calibrate(dh, grid, gravity=grav, tol=tol, harmonics=harm)
        cv = cross_validate(dh, grid, grav, tol, folds, seed, harmonics=harm)
        res[name] = {"calibration": cal.stats, "validation": errors(cal.predict(test), test),
                     "cv": cv}
    return res


def cross_validate(dh, data, grav, tol, folds, seed, harmonics=False):
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(data["q"]))
    errs = []
    for k in range(folds):
        test = np.sort(perm[k::folds])
        train = np.setdiff1d(perm, test)
        cal = calibrate(dh, subset(data, train), gravity=grav, tol=tol, harmonics=harmonics)
        d = subset(data, test)
        p, _ = cal.predict(d)
        errs.append(np.linalg.norm(p - d["p"], axis=1) * 1e3)
    e = np.concatenate(errs)
    return {"folds": folds, "mean_mm": float(e.mean()), "max_mm": float(e.max()),
            "rms_mm": float(np.sqrt(np.mean(e ** 2))),
            "ci95_mean_mm": float(1.96 * e.std(ddof=1) / math.sqrt(e.size)),
            "per_pose_mm": [round(float(v), 5) for v in e]}


UR10_SERIES = {"A": "ur10_A_grid.csv", "B": "ur10_B_joint_configurations.csv",
               "C": "ur10_C_random_poses.csv", "D": "ur10_D_iso_cubes.csv"}


def fifteen_pose_draws(n, draws, seed, first=0):
    """The registration subsets of the 15-pose protocol, draws first .. draws - 1: draw 0 is
    the split of the main table, the others are further random draws of 15 poses (the rest
    evaluated)."""
    for k in range(first, draws):
        r = np.random.default_rng(seed + 1 + k).permutation(n)
        yield np.sort(r[:15]), np.sort(r[15:])


def draw_means(S, draws, seed, register, main):
    """Mean position [mm] and orientation [deg] errors of each draw of 15 registration poses;
    draw 0 is `main`, the main table's errors on the same split."""
    mm, deg = [main["mean_mm"]], [main.get("mean_deg")]
    for reg, ev in fifteen_pose_draws(len(S["q"]), draws, seed, first=1):
        e = errors(register(reg)(subset(S, ev)), subset(S, ev))
        mm.append(e["mean_mm"])
        deg.append(e.get("mean_deg"))
    return {"mean_mm": mm, "mean_deg": deg}


def study_ur10(data_dir, tol=1e-3, seed=0, w_o=1.0, models=UR10_MODELS, draws=10,
               draws_of=("B", "D")):
    dh = robot_dh("ur10")
    d = {k: read_absolute(Path(data_dir) / "ur10" / v) for k, v in UR10_SERIES.items()
         if (Path(data_dir) / "ur10" / v).exists()}
    C = d["C"]
    res = {"dataset": "ur10-landgraf2021", "rows": {k: len(v["q"]) for k, v in d.items()}}
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(C["q"]))
    half = len(perm) // 2
    tr, te = np.sort(perm[:half]), np.sort(perm[half:])
    model, x = uncalibrated(dh, subset(C, tr))
    res["nominal"] = {"half_C": {"calibration": nominal_stats(model, x, subset(C, tr)),
                                 "validation": errors(model.predict(x, subset(C, te)),
                                                      subset(C, te))}}
    for name in models:
        grav, harm = MODEL_SET[name]
        cal_h = calibrate(dh, subset(C, tr), gravity=grav, tol=tol, w_o=w_o, harmonics=harm)
        out = {"half_C": {"calibration": cal_h.stats,
                          "validation": errors(cal_h.predict(subset(C, te)), subset(C, te))}}
        cal = calibrate(dh, C, gravity=grav, tol=tol, w_o=w_o, harmonics=harm)
        out["C"] = {"calibration": cal.stats}
        for k in ("B", "D", "A"):
            if k not in d:
                continue
            S = d[k]
            for label, count in (("20%", None), ("15 poses", 15)):
                r = np.random.default_rng(seed + 1).permutation(len(S["q"]))
                nreg = int(round(0.2 * len(S["q"]))) if count is None else count
                reg, ev = np.sort(r[:nreg]), np.sort(r[nreg:])
                pred = register_session(cal, subset(S, reg), w_o)
                out[f"{k} ({label})"] = errors(pred(subset(S, ev)), subset(S, ev))
            if k in draws_of:
                out[f"{k} (15 poses, draws)"] = draw_means(
                    S, draws, seed, lambda reg: register_session(cal, subset(S, reg), w_o),
                    out[f"{k} (15 poses)"])
        res[name] = out
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dataset", choices=["ur5", "ur10"])
    ap.add_argument("--data-dir", default=str(ROOT / "examples" / "real"))
    ap.add_argument("--tol", type=float, default=1e-3, help="pivoted-QR rank tolerance (relative pivot)")
    ap.add_argument("--json", help="write the results here")
    a = ap.parse_args(argv)
    t = time.perf_counter()
    res = study_ur5(a.data_dir, a.tol) if a.dataset == "ur5" else study_ur10(a.data_dir, a.tol)
    res["total_seconds"] = time.perf_counter() - t
    text = json.dumps(res, indent=1)
    if a.json:
        Path(a.json).write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
