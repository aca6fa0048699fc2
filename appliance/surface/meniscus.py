"""Meniscus: the contact line sits off the free surface; the model and its calibration.

Shared definition (sim/physics.py simulates it): on a surface sloping at beta
(radians from horizontal) the contact line sits h = 2 l_c sin((beta - theta)/2)
above the free surface (l_c capillary length, theta contact angle). A waterline
seen at free-surface level L is therefore the level curve at L + h(beta), and,
seen from a camera at height H above the ink, each of its points is displaced
in the plane towards the camera's foot: a contact point really at height h
above the ink at p + (C - p) h / H appears at p on the liquid plane.

Correction (contact_lines.top_from_apparent): the contact lines are the level curves
of the apparent surface top - h(beta); the fit reconstructs that surface from
them like any waterlines, and the top is solved from it. The rise it gives at
each contact point puts the point back by the perspective for the next pass.
On the top the rise is that of the top's own slope, right up to a wall: at the
sharp edge the contact line pins (the virtual bench renders it so); the ink
climbing the wall itself (h(pi/2)) is hidden behind the wall's edge and wall
points are no data for the top anyway.

The contact line's own curvature: where the line bends round the part (a peak,
a ridge's outside) the meniscus also curves round it and stands lower; where it
bends round the ink (a pit, a crater) higher. To first order in kappa l_c
(Young-Laplace integrated along a straight meniscus' profile)
    h = h_straight sqrt(1 - 2 c f(psi) kappa l_c),  f = (1 - cos^3(psi/2)) / (3 sin^2(psi/2)),
psi = beta - theta, kappa the curvature of the top's level curve through the
contact point (level_curve_curvature: regularised on flats, limited and
averaged over a millimetre). c is the model's `curvature` weight: 1 is the
physics, 0 a straight line; the calibration measures it, so an ink (or a
bench) whose contact lines do not feel their bend gets c ~ 0 and the old
correction back. The solve (contact_lines.py) takes kappa from the top it is solving for (the
contact lines are its level curves), refreshed at every step.

The dissertation's methods, which have no surface to solve on, get a cruder
correction: the slope from the spacing of neighbouring waterlines
(correct_slices_from_spacing).

Calibration: a reference part of known shape (sphere or cone) is scanned; the
(l_c, theta, c) that make every observed point sit on the known surface at
L + h(beta, kappa) are found by robust least squares. On a ball the contact
lines' bend (1/r) and slope change together, yet the three separate: from exact
contact lines of a 30 mm ball they come back to 1e-3.

Faces flatter than the contact angle, which the ink leaves all at once: dewetted.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from ..errors import InkSliceError
from .perspective import Perspective, mark_walls, on_fallen_ink
from .slices import check_waterlines, polyline_distance

CURVATURE_FLAT = 0.05  # slopes under ~3 deg: no level curve to take a curvature of
CURVATURE_LIMIT = 1.0  # |kappa l_c| beyond which the first-order correction stops growing
CURVATURE_CLIP = 0.5  # 1/mm: a tighter bend is a crest's kink, not a contact line's
CURVATURE_SMOOTHING_MM = 1.0
CURVATURE_STEP_MM = 0.2  # the fine grid the curvature is taken on
KNOWN_WEIGHT_MIN = 0.05  # a node this little of whose average falls on known nodes takes the nearest


def curvature_shape(psi):
    """f(psi) of the curvature term: 1/2 on a flat, 0.43 on a vertical wall."""
    half = np.abs(np.asarray(psi, float)) / 2.0
    s2 = np.sin(half) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s2 > 1e-8, (1.0 - np.cos(half) ** 3) / (3.0 * np.maximum(s2, 1e-300)), 0.5)


def level_curve_curvature(
    z,
    hy,
    hx,
    flat=CURVATURE_FLAT,
    clip=CURVATURE_CLIP,
    smoothing_mm=CURVATURE_SMOOTHING_MM,
    known=None,
    along_on_flats=False,
):
    """In-plane curvature (1/mm) of the level curves of a height grid (rows y, columns x):
    -div(grad z / |grad z|), > 0 round a peak, < 0 round a pit; limited to +-clip and
    averaged over smoothing_mm (a meniscus feels the line's mean bend, not a crest's kink).
    `known` (a mask, optional): the nodes where z is the part's top; the average is then
    taken over those alone, and the rest get the nearest average.
    `along_on_flats`: where z is flatter than `flat`, count only the level curve's own bend.
    There the regularised divergence is about the Laplacian over `flat`, which holds the
    second derivative across the level curves as well as along them. Across them it is how
    fast the slope rises out of a flat, which is no bend: on an exact top it makes a narrow
    spike (the plateau's rim, 0.14 mm wide: 0.14/mm after the average), on a fitted top,
    which rounds the rim, a wide one (0.2-0.27/mm three millimetres inside it). Along them
    it is the bend (a dome's summit keeps its circles)."""
    zy, zx = np.gradient(np.asarray(z, float), hy, hx)
    norm = np.sqrt(zx * zx + zy * zy + flat * flat)
    k = -(np.gradient(zx / norm, hx, axis=1) + np.gradient(zy / norm, hy, axis=0))
    if along_on_flats:
        k = _along_on_flats(k, zx, zy, norm, hy, hx, flat)
    k = np.clip(k, -clip, clip)
    sigma = (smoothing_mm / hy, smoothing_mm / hx)
    mean = None if known is None else _mean_over(k, known, sigma)
    return ndimage.gaussian_filter(k, sigma, mode="nearest") if mean is None else mean


def _along_on_flats(k, zx, zy, norm, hy, hx, flat):
    """k blended, by flat^2 / (|grad|^2 + flat^2), into the bend along the level curves alone:
    -z_tt / norm, z_tt the second derivative along the tangent (grad z turned by 90 deg).
    In place, term by term: it runs on the solve's fine curvature grid at every step, where
    the whole expression at once held seven more grids (12 MiB more at the plateau's peak)."""
    zxy, zxx = np.gradient(zx, hy, hx)
    along = zxx * zy
    along *= zy
    zxy *= zx
    zxy *= zy
    along -= 2.0 * zxy
    del zxx, zxy
    zyy = np.gradient(zy, hy, axis=0)
    zyy *= zx
    zyy *= zx
    along += zyy
    del zyy
    g2 = zx * zx
    g2 += zy * zy
    along /= g2 + 1e-12  # z_tt
    along /= norm
    k = k * g2
    k -= flat * flat * along
    g2 += flat * flat
    k /= g2
    return k


def _mean_over(k, known, sigma):
    """The Gaussian mean of k over the `known` nodes alone; nodes whose window holds too
    little of them take the nearest such mean. None when no node has enough."""
    w = ndimage.gaussian_filter(known.astype(float), sigma, mode="constant")
    ok = w > KNOWN_WEIGHT_MIN
    if not ok.any():
        return None
    mean = ndimage.gaussian_filter(np.where(known, k, 0.0), sigma, mode="constant")
    out = np.where(ok, mean / np.where(ok, w, 1.0), np.nan)
    _, (iy, ix) = ndimage.distance_transform_edt(~ok, return_indices=True)
    return out[iy, ix]


@dataclass(frozen=True)
class MeniscusModel:
    capillary_length_mm: float = 2.7
    contact_angle_rad: float = 0.0
    camera_xy_mm: tuple | None = None  # camera centre over the base, for the perspective
    camera_height_mm: float | None = None  # camera centre above the liquid plane
    curvature: float = 0.0  # weight of the contact line's own curvature (1: Young-Laplace)

    def rise(self, beta, kappa=None):
        psi = np.asarray(beta, float) - self.contact_angle_rad
        return 2.0 * self.capillary_length_mm * np.sin(psi / 2.0) * self.curvature_factor(psi, kappa)

    def curvature_factor(self, psi, kappa):
        """h / h_straight where the contact line bends by kappa (1/mm, > 0 round the part)."""
        if kappa is None or self.curvature == 0.0:
            return 1.0
        k = np.clip(
            self.curvature * np.asarray(kappa, float) * self.capillary_length_mm,
            -CURVATURE_LIMIT,
            CURVATURE_LIMIT,
        )
        return np.sqrt(np.maximum(1.0 - 2.0 * curvature_shape(psi) * k, 0.25))

    def rise_on_slope(self, g, kappa=None):
        """h on a surface whose slope (rise over run) is g."""
        return self.rise(np.arctan(g), kappa)

    def rise_on_slope_derivative(self, g, kappa=None):
        """dh / dg (the curvature factor's own slow change with the slope left out)."""
        g = np.asarray(g, float)
        beta = np.arctan(g)
        return (
            self.capillary_length_mm
            * np.cos((beta - self.contact_angle_rad) / 2.0)
            / (1.0 + g * g)
            * self.curvature_factor(beta - self.contact_angle_rad, kappa)
        )

    def scaled(self, f):
        """The same ink with its capillary length times f (the solver turns the meniscus on in steps)."""
        return MeniscusModel(
            f * self.capillary_length_mm,
            self.contact_angle_rad,
            self.camera_xy_mm,
            self.camera_height_mm,
            self.curvature,
        )

    def unproject(self, P, h, sight_mm=None):
        """Plane positions of contact points standing h above the ink; `sight_mm`: the
        camera's height above that ink where the ink fell under it (Slice.sight_mm)."""
        if self.camera_xy_mm is None or not self.camera_height_mm:
            return P
        C = np.asarray(self.camera_xy_mm, float)
        H = self.camera_height_mm if sight_mm is None else np.asarray(sight_mm, float)
        return P + (C - P) * (h / H)[:, None]


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
        t = s.moved(model.unproject(s.P, np.where(s.wall, 0.0, h), s.sight_mm), s.level + h)
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


def _reference_slopes(surface, P, eps=1e-3):
    x, y = P[:, 0], P[:, 1]
    gx = (surface.height(x + eps, y) - surface.height(x - eps, y)) / (2 * eps)
    gy = (surface.height(x, y + eps) - surface.height(x, y - eps)) / (2 * eps)
    return np.hypot(gx, gy)


def _reference_curvature(surface):
    """kappa(P): the curvature of the reference top's level curve through each point P, as
    the correction takes it (level_curve_curvature on a CURVATURE_STEP_MM grid)."""
    x0, x1, y0, y1 = surface.bounds
    step = CURVATURE_STEP_MM
    xs, ys = np.arange(x0 - 2, x1 + 2 + step, step), np.arange(y0 - 2, y1 + 2 + step, step)
    X, Y = np.meshgrid(xs, ys)
    k = level_curve_curvature(surface.height(X, Y), step, step)

    def at(P):
        return ndimage.map_coordinates(
            k, [(P[:, 1] - ys[0]) / step, (P[:, 0] - xs[0]) / step], order=1, mode="nearest"
        )

    return at


def calibrate_meniscus(
    waterlines,
    reference_surface,
    tank_area_mm2=None,
    camera_xy_mm=None,
    camera_height_mm=None,
    wall_tol_mm=0.03,
    ink_falls=False,
) -> MeniscusModel:
    """(l_c, theta) from a scan of a reference part whose `height(x, y)` is known.

    Only points on the sculptured top, well away from the part's outline,
    enter: there the contact line's height is the top's height at the point.
    `ink_falls`: the ink falls under a camera fixed to the tank (scan.json's
    tank.surface_falls); each frame is then seen from the camera's height over its ink.
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
        if ink_falls and camera_xy_mm is not None and camera_height_mm:
            # the fallen ink is further from the camera: its waterlines are further out
            slices = on_fallen_ink(slices, true, Perspective(camera_xy_mm, camera_height_mm))
        slices, _ = correct_slices(slices, tank_area_mm2, true)
    mark_walls(slices, wall_tol_mm)
    on_top, levels, sights = [], [], []
    for s in slices:
        if s.empty:
            continue
        keep = ~s.wall & (_outline_distance(slices, s.P) > 3.0)
        on_top.append(s.P[keep])
        levels.append(np.full(int(keep.sum()), s.level))
        sights.append(np.full(int(keep.sum()), s.sight_mm or camera_height_mm or np.inf))
    if not on_top or sum(len(p) for p in on_top) < 20:
        raise InkSliceError(
            "calibration", "too few waterline points on the reference's top to calibrate the meniscus"
        )
    P, L, S = np.vstack(on_top), np.concatenate(levels), np.concatenate(sights)
    if len(P) > 20000:
        P, L, S = P[:: len(P) // 20000], L[:: len(P) // 20000], S[:: len(P) // 20000]
    beta = np.arctan(_reference_slopes(reference_surface, P))
    curvature = _reference_curvature(reference_surface)
    kappa = curvature(P)
    cam = dict(camera_xy_mm=camera_xy_mm, camera_height_mm=camera_height_mm)

    def residual(params):
        m = MeniscusModel(params[0], params[1], curvature=params[2], **cam)
        h = m.rise(beta, kappa)
        for _ in range(2):  # the slope and curvature where the contact point really is
            Q = m.unproject(P, h, S)
            h = m.rise(np.arctan(_reference_slopes(reference_surface, Q)), curvature(Q))
        return reference_surface.height(*m.unproject(P, h, S).T) - (L + h)

    # the weight is no less than 0: a line bending round the part never raises its meniscus
    sol = least_squares(
        residual,
        x0=[2.0, 0.1, 0.5],
        bounds=([0.0, -np.pi / 2, 0.0], [10.0, np.pi / 2, 3.0]),
        loss="soft_l1",
        f_scale=0.05,
    )
    weight = float(sol.x[2]) if sol.x[2] > 1e-6 else 0.0  # at its bound: a straight line, exactly
    return MeniscusModel(float(sol.x[0]), float(sol.x[1]), curvature=weight, **cam)
