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
That is the two-dimensional meniscus (a straight contact line): h < 0, a
depression, on faces flatter than the contact angle.

A second meniscus model (meniscus_rise_curved) adds the contact line's own
curvature kappa in the plane (1/mm, > 0 where the line bends round the part:
on a peak or the outside of a ridge; < 0 where it bends round the ink: in a
pit or the inside of a crater). The meniscus then also curves round the line's
axis, which takes part of the pressure the rise alone carries in 2-D. Young-
Laplace along the meniscus, z / l_c^2 = k_profile + kappa sin(psi) (psi its
inclination; the second term to first order in kappa l_c, the azimuthal
radius taken as 1 / kappa all the way up) integrates from the flat far ink to
the contact line (psi = beta - theta) as
    h^2 / (2 l_c^2) = 1 - cos(psi) - kappa (4 l_c / 3) (1 - cos^3(psi / 2)),
    h = h_2D(psi) sqrt(1 - 2 f(psi) kappa l_c),  f = (1 - cos^3(psi/2)) / (3 sin^2(psi/2)),
f falling from 1/2 (flat) to 0.43 (vertical): a peak of radius 3 l_c lowers the
rise by ~9 %, a pit of that radius raises it by ~8 %. A depression is the
mirror image and shrinks or grows the same way. Beyond |kappa l_c| = 1 the
first order does not hold: kappa is limited to +-1 / l_c, the root to >= 1/2.
The curvature is that of the level curve of the top through the contact point,
-div(grad top / |grad top|), slopes under CURVATURE_FLAT regularised (a flat
face has no level curve to bend), limited to +-CURVATURE_CLIP and averaged over
CURVATURE_SMOOTHING_MM (the meniscus is wider than that: it feels the line's
mean bend, not a kink on a crest).
"""

from __future__ import annotations

import functools
import math

import numpy as np

CAPILLARY_LENGTH_MM = 2.7
CONTACT_ANGLE_RAD = 0.0
CURVATURE_SMOOTHING_MM = 1.0
CURVATURE_FLAT = 0.05
CURVATURE_CLIP = 0.5


def meniscus_rise(beta, l_c=CAPILLARY_LENGTH_MM, theta=CONTACT_ANGLE_RAD):
    """Height (mm) of the contact line above the free surface on a slope beta (rad)."""
    return 2.0 * l_c * np.sin((np.asarray(beta, float) - theta) / 2.0)


def curvature_shape(psi):
    """f(psi) of the curvature correction: 1/2 on a flat, 0.43 on a vertical wall."""
    half = np.abs(np.asarray(psi, float)) / 2.0
    s2 = np.sin(half) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(s2 > 1e-8, (1.0 - np.cos(half) ** 3) / (3.0 * np.maximum(s2, 1e-300)), 0.5)
    return f


def curvature_factor(psi, kappa, l_c, coefficient=1.0):
    """h / h_2D for a contact line of in-plane curvature kappa (1/mm, > 0 round the part)."""
    k = np.clip(coefficient * np.asarray(kappa, float) * l_c, -1.0, 1.0)
    return np.sqrt(np.maximum(1.0 - 2.0 * curvature_shape(psi) * k, 0.25))


def meniscus_rise_curved(beta, kappa, l_c=CAPILLARY_LENGTH_MM, theta=CONTACT_ANGLE_RAD):
    """Height (mm) of the contact line above the free surface on a slope beta (rad) where
    the line curves by kappa (1/mm) in the plane (the second meniscus model)."""
    psi = np.asarray(beta, float) - theta
    return 2.0 * l_c * np.sin(psi / 2.0) * curvature_factor(psi, kappa, l_c)


def level_curve_curvature(
    z, step_mm, flat=CURVATURE_FLAT, clip=CURVATURE_CLIP, smoothing_mm=CURVATURE_SMOOTHING_MM
):
    """In-plane curvature (1/mm) of the level curves of a height grid z (rows y, columns
    x, spacing step_mm): -div(grad z / |grad z|), > 0 round a peak, < 0 round a pit;
    limited to +-clip and averaged over smoothing_mm (Gaussian sigma)."""
    from scipy import ndimage

    zy, zx = np.gradient(np.asarray(z, float), step_mm)
    norm = np.sqrt(zx * zx + zy * zy + flat * flat)
    nx, ny = zx / norm, zy / norm
    k = np.clip(-(np.gradient(nx, step_mm, axis=1) + np.gradient(ny, step_mm, axis=0)), -clip, clip)
    return ndimage.gaussian_filter(k, smoothing_mm / step_mm, mode="nearest")


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


def true_level(
    surface, nominal_level_mm: float, tank_area_mm2: float, tol: float = 1e-9, max_iter: int = 200
) -> float:
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


def ripple_offset(
    x, y, amplitude_mm, age_s, decay_s=0.6, wavelength_mm=14.0, period_s=0.3, centre=(75.0, 75.0)
):
    """Free-surface height offset (mm) at (x, y): a decaying circular standing wave
    from the tank's centre (where the sleeve lifting the base disturbs it)."""
    a = ripple_amplitude(amplitude_mm, age_s, decay_s)
    if a == 0.0:
        return np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape, np.float32)
    r = np.hypot(np.asarray(x, np.float32) - centre[0], np.asarray(y, np.float32) - centre[1])
    return (a * np.cos(2 * np.pi * r / wavelength_mm) * math.cos(2 * np.pi * age_s / period_s)).astype(
        np.float32
    )
