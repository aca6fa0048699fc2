"""Meniscus: the contact line sits off the free surface; model, correction, calibration.

Shared definition (sim/physics.py simulates it): on a surface sloping at beta
(radians from horizontal) the contact line sits h = 2 l_c sin((beta - theta)/2)
above the free surface (l_c capillary length, theta contact angle). A waterline
seen at free-surface level L is therefore the level curve at L + h(beta), and,
seen from a camera at height H above the ink, each of its points is displaced
in the plane towards the camera's foot: a contact point really at height h
above the ink at p + (C - p) h / H appears at p on the liquid plane.

Correction per waterline point: estimate beta (from the spacing of the
neighbouring waterlines first, then from the current surface fit), then the
point's height is L + h(beta) and its position is moved back by the
perspective. On the top the rise is that of the top's own slope, right up to a
wall: at the sharp edge the contact line pins (the virtual bench renders it so);
the ink climbing the wall itself (h(pi/2)) is hidden behind the wall's edge and
wall points are no data for the top anyway.

Calibration: a reference part of known shape (sphere or cone) is scanned; the
(l_c, theta) that make every observed point sit on the known surface at
L + h(beta) are found by robust least squares.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import InkSliceError
from .slices import check_waterlines, mark_walls, polyline_distance


@dataclass(frozen=True)
class MeniscusModel:
    capillary_length_mm: float = 2.7
    contact_angle_rad: float = 0.0
    camera_xy_mm: tuple | None = None      # camera centre over the base, for the perspective
    camera_height_mm: float | None = None  # camera centre above the liquid plane

    def rise(self, beta):
        return 2.0 * self.capillary_length_mm * np.sin((np.asarray(beta, float) - self.contact_angle_rad) / 2.0)

    def unproject(self, P, h):
        """Plane positions of contact points standing h above the ink."""
        if self.camera_xy_mm is None or not self.camera_height_mm:
            return P
        C = np.asarray(self.camera_xy_mm, float)
        return P + (C - P) * (h / self.camera_height_mm)[:, None]


def camera_centre_xy(K, homography):
    """Camera centre over the base (x, y, mm) from the camera matrix K and the scan's
    homography (undistorted pixel -> liquid plane): the meniscus' perspective needs it."""
    M = np.linalg.inv(np.asarray(K, float)) @ np.linalg.inv(np.asarray(homography, float))
    M = M / np.linalg.norm(M[:, 0])            # ~ [r1 r2 t] of the plane in the camera
    r1, r2, t = M[:, 0], M[:, 1], M[:, 2]
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    C = -R.T @ t
    return float(C[0]), float(C[1])


def _outline_distance(slices, P):
    lowest = next(s for s in reversed(slices) if not s.empty)
    return polyline_distance(lowest, P)[0]


def _corrected(observed, slopes, model):
    out = []
    for s, g in zip(observed, slopes):
        if s.empty:
            out.append(s)
            continue
        g = np.maximum(g, 1e-6)
        beta = np.where(s.wall, np.pi / 2, np.arctan(g))
        h = model.rise(beta)
        # a wall is seen by its top edge, not by the contact line climbing it: only the
        # level-curve points are moved back by the perspective of their raised contact line
        t = s.moved(model.unproject(s.P, np.where(s.wall, 0.0, h)), s.level + h)
        out.append(t)
    return out


def correct_slices_from_spacing(slices, model: MeniscusModel):
    """First estimate: slope = level step / distance to the neighbouring waterlines."""
    slopes = []
    for k, s in enumerate(slices):
        if s.empty:
            slopes.append(np.zeros(0))
            continue
        est = []
        for j in (k - 1, k + 1):
            # to the neighbours' level curves: a wall beside the point is no slope of the top
            cv = slices[j].level_curve() if 0 <= j < len(slices) and not slices[j].empty else None
            if cv is not None and not cv.empty:
                d = polyline_distance(cv, s.P)[0]
                est.append(abs(slices[j].level - s.level) / np.maximum(d, 1e-6))
        slopes.append(np.minimum.reduce(est) if est else np.zeros(len(s.P)))
    return _corrected(slices, slopes, model)


def correct_slices_from_surface(observed, lat, z, footprint, model: MeniscusModel, previous=None):
    """Iteration: slope from the current fit's gradient at each observed point
    -> (corrected slices, slopes). With `previous` (the slopes of the last iteration)
    the new slopes are averaged with them: the rise a slope gives moves the points, the
    points move the next fit, and where the fit is loose (beside a basin no waterline
    crosses) undamped slopes swung 0.07 -> 0.78 -> 0.26 against a true 0.40."""
    from scipy import ndimage
    from .gridfit import bilinear, fill_nearest
    # the slope comes from the fit one node in from the outline: the outline's own nodes
    # sit on the walls, where the fit is least sure, and a step between them and the
    # interior read as slope raised every contact line near the edge, which raises the
    # next fit there (left in, sample 2's edges climbed 1.2 mm in three iterations).
    # The slope itself, not the height, is continued outwards to the rim (a height
    # continued flat reads as no slope: sample 3's ridges came out 1 mm low).
    on = np.isfinite(z) if footprint is None else (footprint & np.isfinite(z))
    inner = ndimage.binary_erosion(on, iterations=1, border_value=0)
    inner = inner if inner.sum() >= 9 else on
    gy, gx = np.gradient(fill_nearest(np.where(inner, z, np.nan)), lat.hy, lat.hx)
    # a central difference is sound where both neighbours are inner nodes
    sound = ndimage.binary_erosion(inner, iterations=1, border_value=0)
    g = np.hypot(gx, gy)
    g = fill_nearest(np.where(sound if sound.any() else inner, g, np.nan))
    slopes = []
    for s in observed:
        if s.empty:
            slopes.append(np.zeros(0))
            continue
        v = bilinear(lat, g, s.P)
        slopes.append(np.where(np.isfinite(v), v, 0.0))
    if previous is not None:
        slopes = [0.5 * (a + b) for a, b in zip(slopes, previous)]
    return _corrected(observed, slopes, model), slopes


def _reference_slopes(surface, P, eps=1e-3):
    x, y = P[:, 0], P[:, 1]
    gx = (surface.height(x + eps, y) - surface.height(x - eps, y)) / (2 * eps)
    gy = (surface.height(x, y + eps) - surface.height(x, y - eps)) / (2 * eps)
    return np.hypot(gx, gy)


def calibrate_meniscus(waterlines, reference_surface, tank_area_mm2=None, camera_xy_mm=None,
                       camera_height_mm=None, wall_tol_mm=0.03) -> MeniscusModel:
    """(l_c, theta) from a scan of a reference part whose `height(x, y)` is known.

    Only points on the sculptured top, well away from the part's outline,
    enter: there the contact line's height is the top's height at the point.
    """
    slices, _ = check_waterlines(waterlines)
    if tank_area_mm2:
        # the reference's shape is known, so is its emerged volume at every level: the
        # waterlines' areas would undercount it by the meniscus being calibrated
        from .displacement import correct_slices, levels_from_surface
        x0, x1, y0, y1 = reference_surface.bounds
        step = max(x1 - x0, y1 - y0) / 500.0
        X, Y = np.meshgrid(np.arange(x0, x1 + step / 2, step), np.arange(y0, y1 + step / 2, step))
        z = np.where(reference_surface.inside(X, Y), reference_surface.height(X, Y), np.nan)
        true = levels_from_surface([s.level for s in slices], z, step * step, tank_area_mm2)
        slices, _ = correct_slices(slices, tank_area_mm2, true)
    mark_walls(slices, wall_tol_mm)
    P, L = [], []
    for s in slices:
        if s.empty:
            continue
        keep = ~s.wall & (_outline_distance(slices, s.P) > 3.0)
        P.append(s.P[keep])
        L.append(np.full(int(keep.sum()), s.level))
    if not P or sum(len(p) for p in P) < 20:
        raise InkSliceError("calibration", "too few waterline points on the reference's top to calibrate the meniscus")
    P, L = np.vstack(P), np.concatenate(L)
    if len(P) > 20000:
        P, L = P[:: len(P) // 20000], L[:: len(P) // 20000]
    beta = np.arctan(_reference_slopes(reference_surface, P))
    cam = dict(camera_xy_mm=camera_xy_mm, camera_height_mm=camera_height_mm)

    def residual(params):
        m = MeniscusModel(params[0], params[1], **cam)
        h = m.rise(beta)
        return reference_surface.height(*m.unproject(P, h).T) - (L + h)

    sol = least_squares(residual, x0=[2.0, 0.1], bounds=([0.0, -np.pi / 2], [10.0, np.pi / 2]),
                        loss="soft_l1", f_scale=0.05)
    return MeniscusModel(float(sol.x[0]), float(sol.x[1]), **cam)
