"""Meniscus: the contact line sits off the free surface; model, correction, calibration.

Shared definition (sim/physics.py simulates it): on a surface sloping at beta
(radians from horizontal) the contact line sits h = 2 l_c sin((beta - theta)/2)
above the free surface (l_c capillary length, theta contact angle). A waterline
seen at free-surface level L is therefore the level curve at L + h(beta), and,
seen from a camera at height H above the ink, each of its points is displaced
in the plane towards the camera's foot: a contact point really at height h
above the ink at p + (C - p) h / H appears at p on the liquid plane.

Correction (top_from_apparent, below): the contact lines are the level curves
of the apparent surface top - h(beta); the fit reconstructs that surface from
them like any waterlines, and the top is solved from it. The rise it gives at
each contact point puts the point back by the perspective for the next pass.
On the top the rise is that of the top's own slope, right up to a wall: at the
sharp edge the contact line pins (the virtual bench renders it so); the ink
climbing the wall itself (h(pi/2)) is hidden behind the wall's edge and wall
points are no data for the top anyway.

The dissertation's methods, which have no surface to solve on, get a cruder
correction: the slope from the spacing of neighbouring waterlines
(correct_slices_from_spacing).

Calibration: a reference part of known shape (sphere or cone) is scanned; the
(l_c, theta) that make every observed point sit on the known surface at
L + h(beta) are found by robust least squares.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.optimize import least_squares
from scipy.sparse.linalg import splu

from ..errors import InkSliceError
from .gridfit import FitProblem, Lattice, bilinear, fill_nearest
from .slices import check_waterlines, mark_walls, polyline_distance


@dataclass(frozen=True)
class MeniscusModel:
    capillary_length_mm: float = 2.7
    contact_angle_rad: float = 0.0
    camera_xy_mm: tuple | None = None      # camera centre over the base, for the perspective
    camera_height_mm: float | None = None  # camera centre above the liquid plane

    def rise(self, beta):
        return 2.0 * self.capillary_length_mm * np.sin((np.asarray(beta, float) - self.contact_angle_rad) / 2.0)

    def rise_on_slope(self, g):
        """h on a surface whose slope (rise over run) is g."""
        return self.rise(np.arctan(g))

    def rise_on_slope_derivative(self, g):
        """dh / dg."""
        g = np.asarray(g, float)
        return self.capillary_length_mm * np.cos((np.arctan(g) - self.contact_angle_rad) / 2.0) / (1.0 + g * g)

    def scaled(self, f):
        """The same ink with its capillary length times f (the solver turns the meniscus on in steps)."""
        return MeniscusModel(f * self.capillary_length_mm, self.contact_angle_rad, self.camera_xy_mm,
                             self.camera_height_mm)

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


# -- the top from its contact lines -------------------------------------------------
#
# The contact line at free-surface level L is where top - h(beta) = L, beta the top's own
# slope there. So the contact lines are exactly the level curves of the apparent surface
#     A = top - h(atan |grad top|),
# which the ordinary fit reconstructs from them as if they were waterlines (first exposure,
# thin plate, cross-validated smoothing: nothing about the meniscus). The top then solves
#     top - h(atan |grad top|) = A
# node by node: a first-order equation, solved as least squares with a little smoothness
# on the rise phi = top - A (third-order, so it bends phi only where its curvature changes)
# by damped Gauss-Newton (Levenberg-Marquardt; h(|grad|) linearised along the slope).
#
# Why not the obvious iteration (rise from the current fit's slope, refit, repeat)? Where
# the top is flat it runs away: raising a contact line steepens the fit's drop beside it,
# which raises the line more. Sample 4's flat corner went from slope 0.12 to 2.3 and 2.4 mm
# too high; elsewhere it took eight fits to settle (sample 1: 0.027 mm after two, 0.011 after
# eight). And why in steps, on every second node first? Where the top is flat the equation
# has near-solutions with bumps on it: a bump phi = K exp(-r / l_c) keeps its contact line at
# its foot, so the data never see it, and Gauss-Newton started far away falls into one
# (sample 4's corner: 2.6 mm). Turning the meniscus on in steps keeps the solution on the
# branch that starts at top = A; the coarse lattice makes the steps cheap and needs a
# smoothness length of three of its spacings (central differences leave grid-scale modes
# free); the full lattice then takes three steps from the coarse answer with one spacing.
# Three, not until it settles (FINE_ITERATIONS): the equation differentiates the frames' noise,
# and the later steps fit it. On rendered physics scans of samples 2/3/4 three steps gave Ea
# 0.014/0.023/0.039 mm, five 0.043/0.025/0.047, eight 0.045/0.038/0.046; on the exact
# apparent surfaces of the tests below eight are better (a dome 0.0068 -> 0.0012 mm), which
# is the price of stopping early.
# The apparent surface's outline nodes are not trusted (RIM_UNTRUSTED): where the top rises
# to a rim, errors there travel inwards (sample 4's rims: 0.22 -> 0.03 mm on the lattice).
# On exact apparent surfaces (a dome, sample 4's saddle) this recovers the top to 0.005 and
# 0.004 mm mean (tests/test_surface_physics.py).

SOLVE_MAX_SIDE = 101      # the rise is smooth: solved on at most this many nodes a side
FINE_ITERATIONS = 3       # Levenberg-Marquardt steps on the full solve lattice
RIM_UNTRUSTED = 2         # nodes next to the outline whose apparent height the solve ignores


def top_from_apparent(lat, apparent, footprint, model: MeniscusModel):
    """-> the top (NaN where `apparent` is) whose contact lines are the level curves of
    `apparent` (the fit of the contact lines as they were seen, on lattice `lat`)."""
    k = max(1, int(np.ceil(max(lat.shape) / SOLVE_MAX_SIDE)))
    sub = Lattice(lat.x[::k], lat.y[::k])
    A = fill_nearest(apparent)[::k, ::k]
    fp = footprint[::k, ::k]
    if fp.sum() < 9:
        return apparent
    h = max(sub.hx, sub.hy)
    if min(sub.shape) >= 20:
        coarse = Lattice(sub.x[::2], sub.y[::2])
        Ac = A[::2, ::2]
        tc = _solve_top(coarse, Ac, fp[::2, ::2], model, 3 * 2 * h, Ac, steps=(0.5, 1.0), iterations=5)
        start = A + _resample_rise(tc - Ac, coarse, sub)
        top = _solve_top(sub, A, fp, model, h, start, steps=(1.0,), iterations=FINE_ITERATIONS)
    else:
        top = _solve_top(sub, A, fp, model, 3 * h, A, steps=(0.5, 1.0), iterations=5)
    rise = top - A if k == 1 else _resample_rise(top - A, sub, lat)
    return np.where(np.isfinite(apparent), apparent + rise, np.nan)


def _resample_rise(phi, src, dst):
    """A rise field (NaN off its unknowns) read on another lattice, bicubic."""
    fi = (dst.x - src.x[0]) / src.hx
    fj = (dst.y - src.y[0]) / src.hy
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    return ndimage.map_coordinates(fill_nearest(phi), [FJ, FI], order=3, mode="nearest")


def _solve_top(lat, A, footprint, model, length_mm, start, steps, iterations, tol=1e-7):
    """Levenberg-Marquardt on |top - h(|grad top|) - A|^2 (footprint nodes) + lam |phi|^2_R3,
    the capillary length turned on in `steps` (fractions of it)."""
    problem = FitProblem(lat, footprint)
    act = problem.active
    Dx, Dy = problem.gradient()
    R = problem.third_order()
    lam = length_mm ** 6 / (lat.hx * lat.hy)
    # the apparent surface's outline nodes are the fit's least sure (their first exposure
    # comes from the wall's waterline, a level step wide): where the top rises to a rim the
    # equation carries their error inwards, so there the top is the smoothness' continuation
    trusted = ndimage.binary_erosion(footprint, iterations=RIM_UNTRUSTED, border_value=0)
    if trusted.sum() < 9:
        trusted = footprint
    a, on = A[act], trusted[act].astype(float)
    I = sp.identity(problem.n, format="csc")
    t = start[act].astype(float)

    def objective(t, m):
        r = on * (t - m.rise_on_slope(np.hypot(Dx @ t, Dy @ t)) - a)
        p = t - a
        return float(r @ r + lam * (p @ (R @ p)))

    mu = 1.0
    for f in steps:
        m = model.scaled(f)
        for _ in range(iterations):
            gx, gy = Dx @ t, Dy @ t
            g = np.hypot(gx, gy)
            r = on * (t - m.rise_on_slope(g) - a)
            c = m.rise_on_slope_derivative(g) / np.sqrt(g * g + 1e-6)   # dh/d(grad) = h' grad / |grad|
            J = sp.diags(on) @ (I - sp.diags(c * gx) @ Dx - sp.diags(c * gy) @ Dy)
            M = (J.T @ J + lam * R).tocsc()
            rhs = -(J.T @ r) - lam * (R @ (t - a))
            f0 = objective(t, m)
            for _ in range(8):
                step = splu((M + mu * I).tocsc(), permc_spec="COLAMD").solve(rhs)
                if objective(t + step, m) < f0:
                    t, mu = t + step, max(mu / 3.0, 1e-8)
                    break
                mu *= 4.0
            else:
                break                          # no step lowers it: as good as it gets
            if np.max(np.abs(step)) < tol:
                break
    out = np.full(lat.shape, np.nan)
    out[act] = t
    return out


def contact_points(slices, lat, rise, model: MeniscusModel):
    """The contact lines' points where they really are, from a rise field on `lat`
    -> (slices at the liquid's level for the apparent surface's fit, slices at
    level + rise for the rest). A point standing h above the ink is seen displaced
    by the perspective (MeniscusModel.unproject); wall points stay as they are (a
    wall is seen by its top edge, put back by slices.unproject_rims)."""
    flat, raised = [], []
    filled = fill_nearest(rise)
    for s in slices:
        if s.empty:
            flat.append(s)
            raised.append(s)
            continue
        h = bilinear(lat, filled, np.column_stack([np.clip(s.P[:, 0], lat.x[0], lat.x[-1]),
                                                   np.clip(s.P[:, 1], lat.y[0], lat.y[-1])]))
        h = np.where(s.wall | ~np.isfinite(h), 0.0, h)
        P = model.unproject(s.P, h)
        flat.append(s.moved(P, s.z))
        raised.append(s.moved(P, s.z + h))
    return flat, raised


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
        for _ in range(2):      # the slope where the contact point really is
            h = m.rise(np.arctan(_reference_slopes(reference_surface, m.unproject(P, h))))
        return reference_surface.height(*m.unproject(P, h).T) - (L + h)

    sol = least_squares(residual, x0=[2.0, 0.1], bounds=([0.0, -np.pi / 2], [10.0, np.pi / 2]),
                        loss="soft_l1", f_scale=0.05)
    return MeniscusModel(float(sol.x[0]), float(sol.x[1]), **cam)
