"""Plotting helpers for notebooks and reports (matplotlib). Every function draws into `ax`
(a new figure when None) and returns the axes."""
from __future__ import annotations

from typing import Optional

import numpy as np

from .api import Dataset, Fit, Model, Robot

__all__ = ["residuals", "prediction_error", "stiffness", "path_deviation"]


def _axes(ax, size=(8, 3)):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=size)[1]


def residuals(fit: Fit, data: Optional[Dataset] = None, ax=None):
    """Residual (measured - predicted) per measurement and axis [um], with the noise floor."""
    ax = _axes(ax)
    r = fit.residuals * 1e6
    x = np.arange(r.shape[0])
    for k, name in enumerate("xyz"):
        ax.bar(x + (k - 1) * 0.27, r[:, k], 0.27, label=f"d{name}")
    floor = fit.statistics.noise_floor_m * 1e6
    if floor > 0:
        for s in (-2 * floor, 2 * floor):
            ax.axhline(s, color="k", lw=0.8, ls="--")
    if data is not None and len(data) <= 40:
        ax.set_xticks(x, data.ids, rotation=90, fontsize=7)
    ax.set_ylabel("residual [um]")
    ax.set_title(f"{'+'.join(fit.model)}: RMS {fit.statistics.rms_m * 1e6:.1f} um"
                 + (f" (noise floor {floor:.1f} um, dashed: 2 sigma)" if floor > 0 else ""))
    ax.legend(fontsize=8)
    return ax


def prediction_error(robot: Robot, fits: dict, data: Dataset, ax=None):
    """Norm of the prediction error per measurement of `data` [um] for several fits
    ({label: Fit}), e.g. before and after adding an effect."""
    ax = _axes(ax)
    x = np.arange(len(data))
    w = 0.8 / max(1, len(fits))
    for i, (label, fit) in enumerate(fits.items()):
        e = data.displacement - Model(robot, fit).predict(data.q, data.wrench)[:, :3]
        n = np.linalg.norm(e, axis=1) * 1e6
        ax.bar(x + (i - (len(fits) - 1) / 2) * w, n, w,
               label=f"{label} (RMS {np.sqrt(np.mean(e ** 2)) * 1e6:.1f} um)")
    ax.set_xlabel("measurement")
    ax.set_ylabel("|error| [um]")
    ax.legend(fontsize=8)
    return ax


def stiffness(fit: Fit, truth=None, ax=None):
    """Identified joint stiffness with 2-sigma bars [N*m/rad], optionally beside the truth."""
    ax = _axes(ax, (6, 3))
    k, se = fit.stiffness, fit.stiffness_se
    j = np.arange(1, k.size + 1)
    ok = np.isfinite(k)
    ax.errorbar(j[ok], k[ok], yerr=2 * np.nan_to_num(se[ok]), fmt="o", capsize=3, label="identified")
    if truth is not None:
        ax.plot(j, truth, "x", color="k", label="true")
    ax.set_yscale("log")
    ax.set_xticks(j)
    ax.set_xlabel("joint")
    ax.set_ylabel("k [N*m/rad]")
    ax.legend(fontsize=8)
    return ax


def path_deviation(path_xyz, curves: dict, output, title: str = ""):
    """Path (top view) and deviation along it; see stiff.compensate.plot_deviation."""
    from .compensate import plot_deviation

    return plot_deviation(path_xyz, curves, output, title)
