"""The ink's physics on the virtual bench: displacement, meniscus, ripple.

All three are shared definitions (the surface team corrects the first two with
the same formulas), so they live here as small pure functions.

Displacement: the nominal level of a frame assumes the part fully submerged.
As the part emerges the ink level drops:
    L_true = L_nominal - V_emerged(L_true) / A_tank,
    V_emerged(L) = integral over the base plane of max(height(x, y) - L, 0),
solved by fixed point (a contraction: dV/dL is minus the emerged area, always
smaller than the tank's area).

Meniscus: where the part's surface slopes at beta (radians from horizontal,
pi/2 on a vertical wall) the contact line sits h = 2 l_c sin((beta - theta)/2)
above the free surface; l_c is the capillary length, theta the contact angle.
"""
from __future__ import annotations

import functools
import math

import numpy as np

CAPILLARY_LENGTH_MM = 2.7
CONTACT_ANGLE_RAD = 0.0


def meniscus_rise(beta, l_c=CAPILLARY_LENGTH_MM, theta=CONTACT_ANGLE_RAD):
    """Height (mm) of the contact line above the free surface on a slope beta (rad)."""
    return 2.0 * l_c * np.sin((np.asarray(beta, float) - theta) / 2.0)


@functools.lru_cache(maxsize=16)
def _height_samples(surface, cell_mm: float):
    xmin, xmax, ymin, ymax = surface.bounds
    nx = max(2, int(math.ceil((xmax - xmin) / cell_mm)))
    ny = max(2, int(math.ceil((ymax - ymin) / cell_mm)))
    # cell centres (midpoint rule: second-order accurate for smooth tops)
    xs = xmin + (np.arange(nx) + 0.5) * (xmax - xmin) / nx
    ys = ymin + (np.arange(ny) + 0.5) * (ymax - ymin) / ny
    X, Y = np.meshgrid(xs, ys)
    area = (xmax - xmin) / nx * (ymax - ymin) / ny
    return np.sort(surface.height(X, Y).ravel()), area


def emerged_volume(surface, level_mm: float, cell_mm: float = 0.2) -> float:
    """V_emerged(L) in mm^3: the part's volume above the liquid at level L."""
    h, area = _height_samples(surface, cell_mm)
    i = np.searchsorted(h, level_mm, side="right")
    return float(np.sum(h[i:] - level_mm) * area)


def emerged_area(surface, level_mm: float, cell_mm: float = 0.2) -> float:
    """Area (mm^2) of the part's cross-section at level L (= -dV/dL)."""
    h, area = _height_samples(surface, cell_mm)
    return float((h.size - np.searchsorted(h, level_mm, side="right")) * area)


def true_level(surface, nominal_level_mm: float, tank_area_mm2: float,
               tol: float = 1e-9, max_iter: int = 200) -> float:
    """Solve L = L_nominal - V_emerged(L) / A_tank by fixed point."""
    if tank_area_mm2 <= 0:
        raise ValueError("tank area must be positive")
    L = float(nominal_level_mm)
    for _ in range(max_iter):
        L_new = nominal_level_mm - emerged_volume(surface, L) / tank_area_mm2
        if abs(L_new - L) < tol:
            return L_new
        L = L_new
    return L


def ripple_amplitude(amplitude_mm: float, age_s: float, decay_s: float) -> float:
    """Amplitude of the free surface's oscillation `age_s` after a move stopped."""
    if amplitude_mm <= 0 or age_s is None:
        return 0.0
    return float(amplitude_mm * math.exp(-max(age_s, 0.0) / max(decay_s, 1e-9)))


def ripple_offset(x, y, amplitude_mm, age_s, decay_s=0.6, wavelength_mm=14.0,
                  period_s=0.3, centre=(75.0, 75.0)):
    """Free-surface height offset (mm) at (x, y): a decaying circular standing wave
    from the tank's centre (where the sleeve lifting the base disturbs it)."""
    a = ripple_amplitude(amplitude_mm, age_s, decay_s)
    if a == 0.0:
        return np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape, np.float32)
    r = np.hypot(np.asarray(x, np.float32) - centre[0], np.asarray(y, np.float32) - centre[1])
    return (a * np.cos(2 * np.pi * r / wavelength_mm) * math.cos(2 * np.pi * age_s / period_s)).astype(np.float32)
