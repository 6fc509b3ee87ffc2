"""Milling forces from the Kienzle specific cutting force (docs/olp.md).

Kienzle (1952): the specific cutting force falls with the uncut chip thickness h,
    k_c(h) = k_c1.1 * (h / 1 mm)^(-m_c)      [N/mm^2],
so a cutting edge of width b [mm] cutting a chip of thickness h carries the tangential force
F_t = b * h * k_c(h) = b * k_c1.1 * h^(1 - m_c) [N]. In milling (Altintas, Manufacturing
Automation, ch. 2) the chip thickness of a tooth at immersion angle phi is h = f_z sin(phi);
each tooth also pushes radially (F_r = K_r F_t) and axially (F_a = K_a F_t). The robot's
quasi-static deflection answers to the force averaged over one tooth period, computed here by
quadrature over the engagement arc:

    F_x = -F_t cos(phi) - F_r sin(phi)     (feed direction)
    F_y = +F_t sin(phi) - F_r cos(phi)     (normal to the feed, in the cutting plane)
    F_z = F_a                               (along the tool axis, towards the spindle)

(the force on the tool; cutter rotating clockwise seen from the spindle, phi from the +y axis)
with phi in [0, phi_ex], phi_ex = arccos(1 - 2 a_e / D) for up-milling and
[pi - phi_ex, pi] for down-milling, mean = z / (2 pi) * integral."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["KienzleMaterial", "MATERIALS", "MillingCut", "mean_force", "specific_cutting_force",
           "mean_chip_thickness", "milling_wrench"]


@dataclass(frozen=True)
class KienzleMaterial:
    """Kienzle constants: k_c1.1 [N/mm^2] (specific cutting force at h = b = 1 mm) and m_c."""

    kc11: float
    mc: float
    name: str = ""


# Handbook values of the Kienzle constants (k_c1.1 [N/mm^2], m_c) for a rake angle of about 6
# degrees, as tabulated in the machining literature (Koenig and Klocke, Fertigungsverfahren 1;
# Paucksch et al., Zerspantechnik). Real values vary with the batch, the tool and the wear:
# measure or take the tool maker's values for production.
MATERIALS = {
    "S235": KienzleMaterial(1780.0, 0.17, "S235JR (St 37) structural steel"),
    "C45": KienzleMaterial(2220.0, 0.14, "C45E (Ck 45) carbon steel"),
    "42CrMo4": KienzleMaterial(2500.0, 0.26, "42CrMo4 alloyed steel"),
    "16MnCr5": KienzleMaterial(2100.0, 0.26, "16MnCr5 case-hardening steel"),
    "EN-GJL-200": KienzleMaterial(1020.0, 0.25, "EN-GJL-200 (GG 20) grey cast iron"),
    "AlMg3": KienzleMaterial(780.0, 0.23, "AlMg3 wrought aluminium"),
}


def specific_cutting_force(material: KienzleMaterial, h_mm) -> np.ndarray:
    """k_c(h) = k_c1.1 h^-m_c [N/mm^2] at uncut chip thickness h [mm]."""
    h = np.asarray(h_mm, dtype=float)
    if np.any(h <= 0):
        raise ValueError("the chip thickness must be positive")
    return material.kc11 * h ** (-material.mc)


@dataclass(frozen=True)
class MillingCut:
    """Engagement of a milling cut (lengths in mm)."""

    diameter: float       # D, tool diameter
    teeth: int            # z
    feed_per_tooth: float  # f_z [mm]
    width: float          # a_e, radial width of cut
    depth: float          # a_p, axial depth of cut
    down_milling: bool = True
    radial_ratio: float = 0.3  # K_r = F_r / F_t
    axial_ratio: float = 0.0   # K_a = F_a / F_t (helix and nose radius)

    def check(self) -> None:
        for name in ("diameter", "feed_per_tooth", "width", "depth"):
            if not getattr(self, name) > 0:
                raise ValueError(f"milling cut: {name} must be positive")
        if self.teeth < 1:
            raise ValueError("milling cut: teeth must be >= 1")
        if self.width > self.diameter:
            raise ValueError(f"milling cut: width of cut a_e = {self.width} mm exceeds the tool "
                             f"diameter {self.diameter} mm")

    def arc(self) -> tuple[float, float]:
        phi = math.acos(1.0 - 2.0 * self.width / self.diameter)
        return (math.pi - phi, math.pi) if self.down_milling else (0.0, phi)


def mean_chip_thickness(cut: MillingCut) -> float:
    """Arc-mean uncut chip thickness h_m = f_z (cos phi_st - cos phi_ex) / (phi_ex - phi_st) [mm]."""
    a, b = cut.arc()
    return cut.feed_per_tooth * (math.cos(a) - math.cos(b)) / (b - a)


def mean_force(material: KienzleMaterial, cut: MillingCut, samples: int = 2001) -> np.ndarray:
    """Tooth-period mean force on the tool [N], (feed, normal, axial) components (module
    docstring). Simpson quadrature over the engagement arc (the integrand is smooth inside)."""
    cut.check()
    a, b = cut.arc()
    phi = np.linspace(a, b, samples | 1)
    h = cut.feed_per_tooth * np.sin(phi)
    ft = cut.depth * material.kc11 * np.clip(h, 0.0, None) ** (1.0 - material.mc)
    fr = cut.radial_ratio * ft
    comp = np.stack([-ft * np.cos(phi) - fr * np.sin(phi), ft * np.sin(phi) - fr * np.cos(phi),
                     cut.axial_ratio * ft])
    w = np.ones(phi.size)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    integral = comp @ w * (phi[1] - phi[0]) / 3.0
    return cut.teeth / (2.0 * math.pi) * integral


def milling_wrench(material: KienzleMaterial, cut: MillingCut, pose: np.ndarray,
                   previous_position) -> np.ndarray:
    """Wrench (F [N], M = 0) on the tool at `pose` (4 x 4, tool axis = z) cutting along the
    motion from `previous_position` (same frame): mean_force's feed, normal and axial
    components resolved on the feed direction projected normal to the tool axis, axis x feed,
    and -axis (the axial force pushes the tool back towards the spindle). Zero without a feed
    direction (first target, or a plunge along the tool axis)."""
    w = np.zeros(6)
    if previous_position is None:
        return w
    axis = pose[:3, 2]
    feed = pose[:3, 3] - np.asarray(previous_position, dtype=float)
    feed = feed - axis * (feed @ axis)
    if np.linalg.norm(feed) <= 1e-9:
        return w
    x = feed / np.linalg.norm(feed)
    fx, fy, fa = mean_force(material, cut)
    w[:3] = fx * x + fy * np.cross(axis, x) - fa * axis
    return w
