"""Peer implementation: the paper's simulated annealing written the way a researcher would in
numpy. It rebuilds the stacked observation matrix A of the current set from the precomputed pool
Jacobians at every step and evaluates kappa_F^-1(A) = m / sqrt(tr(A^T A) tr((A^T A)^-1)).

Same algorithm as stiff::anneal (docs/planning.md): k-element swaps with k falling linearly from
k0 to 1, Metropolis acceptance exp(-Delta/T) on the cost kappa_F(A), linear cooling from T0
(by default a hundredth of the mean cost increase of 200 random k0-swaps, as stiff's).
"""
import math
import struct
import time

import numpy as np


def load_pool(path):
    """Read the pool written by `stiff_plan_benchmark --dump-pool`."""
    with open(path, "rb") as f:
        if f.read(9) != b"STIFFPOOL":
            raise ValueError(path + ": not a pool dump")
        P, L, E, m = struct.unpack("<4i", f.read(16))
        per_pose = np.frombuffer(f.read(P * (6 * m + 1) * 8), dtype="<f8").reshape(P, 6 * m + 1)
        jm = per_pose[:, : 3 * m].reshape(P, m, 3).transpose(0, 2, 1)  # (P, 3, m)
        jl = per_pose[:, 3 * m : 6 * m].reshape(P, m, 3).transpose(0, 2, 1)
        w2 = per_pose[:, 6 * m]
        forces = np.frombuffer(f.read(L * 3 * 8), dtype="<f8").reshape(L, 3)
        elems = np.frombuffer(f.read(E * 8), dtype="<i4").reshape(E, 2)
    return {"jm": jm, "jl": jl, "w2": w2, "forces": forces, "pose": elems[:, 0], "load": elems[:, 1], "m": m}


def stacked_a(pool, chosen):
    """Stacked, row-weighted observation matrix (3N x m) of the chosen elements."""
    p = pool["pose"][chosen]
    l = pool["load"][chosen]
    tau = np.einsum("nrk,nr->nk", pool["jl"][p], pool["forces"][l])  # J_l^T F per joint
    a = pool["jm"][p] * tau[:, None, :] * np.sqrt(pool["w2"][p])[:, None, None]
    return a.reshape(-1, pool["m"])


def kappa_inv(a):
    ata = a.T @ a
    try:
        inv = np.linalg.inv(ata)
    except np.linalg.LinAlgError:
        return 0.0
    t = np.trace(ata) * np.trace(inv)
    return a.shape[1] / math.sqrt(t) if t > 0 else 0.0


def anneal(pool, count=10, iterations=10000, seed=1, t0=None, k0=None):
    rng = np.random.default_rng(seed)
    size = len(pool["pose"])
    chosen = rng.choice(size, count, replace=False)
    cost = 1.0 / max(kappa_inv(stacked_a(pool, chosen)), 1e-300)
    best, best_cost = chosen.copy(), cost
    k0 = k0 or max(1, count // 3)

    def propose(k):
        new = chosen.copy()
        pos = rng.choice(count, k, replace=False)
        for p in pos:
            e = rng.integers(size)
            while e in new:
                e = rng.integers(size)
            new[p] = e
        kap = kappa_inv(stacked_a(pool, new))
        return new, (1.0 / kap if kap > 0 else math.inf)

    if t0 is None:
        ups = [c - cost for _, c in (propose(k0) for _ in range(200)) if math.isfinite(c) and c > cost]
        # stiff's automatic T0 (AnnealingOptions::automatic_temperature_fraction = 0.01)
        t0 = 0.01 * float(np.mean(ups)) if ups else 1e-3 * cost
    for it in range(iterations):
        frac = it / iterations
        k = max(1, math.ceil(k0 * (1 - frac)))
        temp = t0 * (1 - frac)
        new, c = propose(k)
        if c <= cost or (temp > 0 and math.isfinite(c) and rng.random() < math.exp(-(c - cost) / temp)):
            chosen, cost = new, c
            if cost < best_cost:
                best, best_cost = chosen.copy(), cost
    return best, 1.0 / best_cost


def swaps_per_second(pool, count=10, iterations=5000, seed=1):
    t = time.perf_counter()
    _, kappa = anneal(pool, count, iterations, seed)
    dt = time.perf_counter() - t
    return iterations / dt, kappa, dt


if __name__ == "__main__":
    import sys

    pool = load_pool(sys.argv[1])
    rate, kappa, dt = swaps_per_second(pool, iterations=int(sys.argv[2]) if len(sys.argv) > 2 else 5000)
    print(f"numpy annealing: {rate:.4g} swaps/s, kappa_a {kappa:.5f}, {dt:.3f} s")
