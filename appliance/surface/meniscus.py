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
correction back. The solve takes kappa from the top it is solving for (the
contact lines are its level curves), refreshed at every step.

The dissertation's methods, which have no surface to solve on, get a cruder
correction: the slope from the spacing of neighbouring waterlines
(correct_slices_from_spacing).

Calibration: a reference part of known shape (sphere or cone) is scanned; the
(l_c, theta, c) that make every observed point sit on the known surface at
L + h(beta, kappa) are found by robust least squares. On a ball the contact
lines' bend (1/r) and slope change together, yet the three separate: from exact
contact lines of a 30 mm ball they come back to 1e-3.
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

CURVATURE_FLAT = 0.05  # slopes under ~3 deg: no level curve to take a curvature of
CURVATURE_LIMIT = 1.0  # |kappa l_c| beyond which the first-order correction stops growing
CURVATURE_CLIP = 0.5  # 1/mm: a tighter bend is a crest's kink, not a contact line's
CURVATURE_SMOOTHING_MM = 1.0


def curvature_shape(psi):
    """f(psi) of the curvature term: 1/2 on a flat, 0.43 on a vertical wall."""
    half = np.abs(np.asarray(psi, float)) / 2.0
    s2 = np.sin(half) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s2 > 1e-8, (1.0 - np.cos(half) ** 3) / (3.0 * np.maximum(s2, 1e-300)), 0.5)


def level_curve_curvature(
    z, hy, hx, flat=CURVATURE_FLAT, clip=CURVATURE_CLIP, smoothing_mm=CURVATURE_SMOOTHING_MM
):
    """In-plane curvature (1/mm) of the level curves of a height grid (rows y, columns x):
    -div(grad z / |grad z|), > 0 round a peak, < 0 round a pit; limited to +-clip and
    averaged over smoothing_mm (a meniscus feels the line's mean bend, not a crest's kink)."""
    zy, zx = np.gradient(np.asarray(z, float), hy, hx)
    norm = np.sqrt(zx * zx + zy * zy + flat * flat)
    k = np.clip(-(np.gradient(zx / norm, hx, axis=1) + np.gradient(zy / norm, hy, axis=0)), -clip, clip)
    return ndimage.gaussian_filter(k, (smoothing_mm / hy, smoothing_mm / hx), mode="nearest")


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

    def unproject(self, P, h):
        """Plane positions of contact points standing h above the ink."""
        if self.camera_xy_mm is None or not self.camera_height_mm:
            return P
        C = np.asarray(self.camera_xy_mm, float)
        return P + (C - P) * (h / self.camera_height_mm)[:, None]


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

SOLVE_MAX_SIDE = 101  # the rise is smooth: solved on at most this many nodes a side
FINE_ITERATIONS = 3  # Levenberg-Marquardt steps on the full solve lattice
RIM_UNTRUSTED = 2  # nodes next to the outline whose apparent height the solve ignores


def top_from_apparent(lat, apparent, footprint, model: MeniscusModel, faces=None):
    """-> the top (NaN where `apparent` is) whose contact lines are the level curves of
    `apparent` (the fit of the contact lines as they were seen, on lattice `lat`).
    `faces`: nodes of faces that came out at once (dewetted_nodes). No contact line crossed
    them, so no line's bend changes their depression: there the curvature term is left out
    (else the fit's ripples on a flat face, divided by CURVATURE_FLAT, read as bends: the
    steep front's apron came out 0.18 mm high)."""
    k = max(1, int(np.ceil(max(lat.shape) / SOLVE_MAX_SIDE)))
    sub = Lattice(lat.x[::k], lat.y[::k])
    A = fill_nearest(apparent)[::k, ::k]
    fp = footprint[::k, ::k]
    if fp.sum() < 9:
        return apparent
    h = max(sub.hx, sub.hy)
    straight = None if faces is None else faces[::k, ::k]
    kappa = contact_line_curvature(sub, A) if model.curvature else None
    if min(sub.shape) >= 20:
        coarse = Lattice(sub.x[::2], sub.y[::2])
        Ac = A[::2, ::2]
        kc = None if kappa is None else kappa[::2, ::2]
        tc = _solve_top(
            coarse,
            Ac,
            fp[::2, ::2],
            model,
            3 * 2 * h,
            Ac,
            steps=(0.5, 1.0),
            iterations=5,
            kappa=kc,
            straight=None if straight is None else straight[::2, ::2],
        )
        start = A + _resample_rise(tc - Ac, coarse, sub)
        top = _solve_top(
            sub,
            A,
            fp,
            model,
            h,
            start,
            steps=(1.0,),
            iterations=FINE_ITERATIONS,
            kappa=kappa,
            straight=straight,
        )
    else:
        top = _solve_top(
            sub, A, fp, model, 3 * h, A, steps=(0.5, 1.0), iterations=5, kappa=kappa, straight=straight
        )
    rise = top - A if k == 1 else _resample_rise(top - A, sub, lat)
    return np.where(np.isfinite(apparent), apparent + rise, np.nan)


CURVATURE_STEP_MM = 0.2  # the fine grid the curvature is taken on


def contact_line_curvature(lat, top):
    """The contact lines' own curvature (1/mm) at every node: that of the top's level curves,
    taken on a CURVATURE_STEP_MM grid (bicubic from the lattice) so that a crest's clipped
    spike is as narrow as it really is, whatever the lattice's spacing."""
    ky = max(1, int(np.ceil(lat.hy / CURVATURE_STEP_MM)))
    kx = max(1, int(np.ceil(lat.hx / CURVATURE_STEP_MM)))
    fj = np.arange((top.shape[0] - 1) * ky + 1) / ky
    fi = np.arange((top.shape[1] - 1) * kx + 1) / kx
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    fine = ndimage.map_coordinates(top, [FJ, FI], order=3, mode="nearest")  # C2: curvature needs it
    return level_curve_curvature(fine, lat.hy / ky, lat.hx / kx)[::ky, ::kx]


def _resample_rise(phi, src, dst):
    """A rise field (NaN off its unknowns) read on another lattice, bicubic."""
    fi = (dst.x - src.x[0]) / src.hx
    fj = (dst.y - src.y[0]) / src.hy
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    return ndimage.map_coordinates(fill_nearest(phi), [FJ, FI], order=3, mode="nearest")


def _solve_top(
    lat, A, footprint, model, length_mm, start, steps, iterations, tol=1e-7, kappa=None, straight=None
):
    """Levenberg-Marquardt on |top - h(|grad top|) - A|^2 (footprint nodes) + lam |phi|^2_R3,
    the capillary length turned on in `steps` (fractions of it)."""
    problem = FitProblem(lat, footprint)
    act = problem.active
    Dx, Dy = problem.gradient()
    R = problem.third_order()
    lam = length_mm**6 / (lat.hx * lat.hy)
    # the apparent surface's outline nodes are the fit's least sure (their first exposure
    # comes from the wall's waterline, a level step wide): where the top rises to a rim the
    # equation carries their error inwards, so there the top is the smoothness' continuation
    trusted = ndimage.binary_erosion(footprint, iterations=RIM_UNTRUSTED, border_value=0)
    if trusted.sum() < 9:
        trusted = footprint
    a, on = A[act], trusted[act].astype(float)
    I = sp.identity(problem.n, format="csc")
    t = start[act].astype(float)
    curved = kappa is not None

    keep = 1.0 if straight is None else (~straight[act]).astype(float)

    def curvature_of(t):
        """The contact lines' curvature where the top is t: that of its level curves."""
        full = np.full(lat.shape, np.nan)
        full[act] = t
        return contact_line_curvature(lat, fill_nearest(full))[act] * keep

    kap = kappa[act] * keep if curved else None

    def objective(t, m):
        r = on * (t - m.rise_on_slope(np.hypot(Dx @ t, Dy @ t), kap) - a)
        p = t - a
        return float(r @ r + lam * (p @ (R @ p)))

    mu = 1.0
    for f in steps:
        m = model.scaled(f)
        for _ in range(iterations):
            if curved:
                kap = curvature_of(t)
            gx, gy = Dx @ t, Dy @ t
            g = np.hypot(gx, gy)
            r = on * (t - m.rise_on_slope(g, kap) - a)
            c = m.rise_on_slope_derivative(g, kap) / np.sqrt(g * g + 1e-6)  # dh/d(grad) = h' grad / |grad|
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
                break  # no step lowers it: as good as it gets
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
        h = bilinear(
            lat,
            filled,
            np.column_stack(
                [np.clip(s.P[:, 0], lat.x[0], lat.x[-1]), np.clip(s.P[:, 1], lat.y[0], lat.y[-1])]
            ),
        )
        h = np.where(s.wall | ~np.isfinite(h), 0.0, h)
        P = model.unproject(s.P, h)
        flat.append(s.moved(P, s.z))
        raised.append(s.moved(P, s.z + h))
    return flat, raised


# -- faces flatter than the contact angle: a depression ----------------------------------
#
# On a face flatter than the contact angle the contact line sits d = -h(0) below the free
# surface (a puddle of this ink is d deep): a flat face at z stays under until the ink is
# d above it and then comes out all at once, between two frames, with no contact line ever
# crossing it. What the frames say about it is a bracket: out at L_k, under at L_(k-1), so
# its apparent height A = z + d lies in (L_k, L_(k-1)]; nothing finer (the rendered second
# ink's twin-peaks: A = 7.38 in (6.70, 7.91]). Before, such faces came out at the bracket's
# bottom or anywhere the fit ran on to (twin-peaks' 6 mm skirt 0.62 mm low, the crater's
# outer band 0.26-0.67, the steep front's apron likewise). Now:
#  - in the frame that uncovered a face, its rim is a wall (pinned_rims_as_walls). The ink
#    stands up to d above the rim then, pinned at the sharp edge: the waterline along the
#    outline is that edge, seen up to d below the ink, not a level curve of A at L_k; nor
#    does it stay put in perspective like an edge above the ink, so the wall test misses it;
#  - nodes well inside such a face (no contact line of frame k within l_c, the meniscus'
#    reach, and the one above further than its own spacing says) go to the middle of their
#    bracket, never more than half a step out (place_dewetted_faces); the rest of the face's
#    nodes are held in the bracket after the fit (bracket_dewetted_faces).
# Within half a step is what the frames allow: a finer level step near the face, not a
# cleverer fit, is what would place it closer.


DEPRESSION_MIN_MM = 0.05  # shallower, a flat face comes out within that of its height


def depression_depth(model: MeniscusModel) -> float:
    """d = -h(0): how far the ink stands above a flat face it has just left; 0 for an ink
    that wets it or one whose depression is under DEPRESSION_MIN_MM (the first ink commissions
    to 0.04 deg: 0.002 mm)."""
    d = -float(model.rise(0.0))
    return d if d >= DEPRESSION_MIN_MM else 0.0


def pinned_rims_as_walls(slices, model: MeniscusModel, wall_tol_mm):
    """-> slices whose pinned rims are walls: stretches along the part's outline (the lowest
    frame's waterline) with no contact line of the frame above within l_c (the face inside
    was under ink there a frame ago and came out at once). Along the outline means within
    what a rim seen up to 3 d off its height moves in perspective (d for the pinned edge
    itself, the rest for the lowest frame's edges, put back with the fit's rim heights).
    Only with a depression (d > 0): otherwise the slices as they are."""
    d = depression_depth(model)
    visible = [k for k, s in enumerate(slices) if not s.empty]
    if d <= 0 or len(visible) < 3:
        return slices
    lowest = slices[visible[-1]]
    out = list(slices)
    for k in visible[1:-1]:
        s = slices[k]
        wall = np.zeros(len(s.P), bool) if s.wall is None else s.wall
        if wall.all():
            continue
        tol = np.full(len(s.P), wall_tol_mm + 0.02)
        if model.camera_xy_mm is not None and model.camera_height_mm:
            r = np.hypot(*(s.P - np.asarray(model.camera_xy_mm, float)).T)
            tol += 3.0 * d * r / model.camera_height_mm
        pinned = ~wall & (polyline_distance(lowest, s.P)[0] < tol)
        if pinned.any():
            # ... and only where the face inside came out at once: no contact line above
            # within the meniscus' reach
            i = np.flatnonzero(pinned)
            pinned[i] = _distance_to_contact_line(slices, k - 1, s.P[i]) > model.capillary_length_mm
        if not pinned.any():
            continue
        t = s.moved(s.P, s.z)
        t.wall = wall | pinned
        out[k] = t
    return out


def _distance_to_contact_line(slices, k, q):
    top = next(j for j, s in enumerate(slices) if not s.empty)
    return polyline_distance(slices[k].level_curve(), q)[0] if k >= top else np.full(len(q), np.inf)


FACE_SPACINGS = 2  # a face: its contact line above is this many of their spacings away


def _dewetted(lat, z_fe, first, footprint, slices, model):
    """-> [(frame k, node indices, deep)] for the nodes no contact line placed (no first-exposure
    height) and none of the frame k that uncovered them passes within the meniscus' reach
    (l_c); `deep`: also further from frame k - 1's contact line than FACE_SPACINGS times the
    spacing from there to frame k - 2's, plus 2 l_c): well inside a face, not at the bottom of
    a bowl, which the fit continues the contact lines above into (a paraboloid: 0.01 mm)."""
    K = len(slices)
    top = next(k for k, s in enumerate(slices) if not s.empty)
    todo = footprint & ~np.isfinite(z_fe) & (first > top) & (first < K)
    out = []
    if depression_depth(model) <= 0 or not todo.any():
        return out
    X, Y = np.meshgrid(lat.x, lat.y)
    reach = model.capillary_length_mm
    for k in np.unique(first[todo]):
        sel = todo & (first == k)
        q = np.column_stack([X[sel], Y[sel]])
        far = _distance_to_contact_line(slices, k, q) > reach
        d_up = _distance_to_contact_line(slices, k - 1, q[far])
        d_up2 = _distance_to_contact_line(slices, k - 2, q[far])
        with np.errstate(invalid="ignore"):
            spacing = np.where(np.isfinite(d_up2), np.abs(d_up2 - d_up), d_up)
        out.append((int(k), np.flatnonzero(sel.ravel())[far], d_up > FACE_SPACINGS * spacing + 2 * reach))
    return out


def dewetted_nodes(lat, z_fe, first, footprint, slices, model: MeniscusModel):
    """-> mask of the nodes of faces that came out at once (those place_dewetted_faces and
    bracket_dewetted_faces hold in their brackets), or None when there are none."""
    found = _dewetted(lat, z_fe, first, footprint, slices, model)
    if not found:
        return None
    mask = np.zeros(lat.shape, bool)
    for _, idx, _ in found:
        mask.ravel()[idx] = True
    return mask


def place_dewetted_faces(lat, z_fe, first, footprint, slices, model: MeniscusModel):
    """First-exposure heights for the nodes well inside faces that came out all at once: the
    middle of their bracket (L_k, L_(k-1)], never more than half a step out. Only with a
    depression."""
    out = z_fe
    for k, idx, deep in _dewetted(lat, z_fe, first, footprint, slices, model):
        if deep.any():
            out = out.copy() if out is z_fe else out
            out.ravel()[idx[deep]] = 0.5 * (slices[k].level + slices[k - 1].level)
    return out


def bracket_dewetted_faces(lat, apparent, z_fe, first, footprint, slices, model: MeniscusModel):
    """The fitted apparent surface with the rest of those nodes (at a face's edge) held in
    their bracket: the fit continues the contact lines above into them, which on a skirt
    flattening into a face runs on past the level that still covered it (an ideal twin-peaks:
    0.5-1.3 mm high). Only with a depression."""
    out = apparent
    for k, idx, _ in _dewetted(lat, z_fe, first, footprint, slices, model):
        out = out.copy() if out is apparent else out
        out.ravel()[idx] = np.clip(out.ravel()[idx], slices[k].level, slices[k - 1].level)
    return out


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
) -> MeniscusModel:
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
        raise InkSliceError(
            "calibration", "too few waterline points on the reference's top to calibrate the meniscus"
        )
    P, L = np.vstack(P), np.concatenate(L)
    if len(P) > 20000:
        P, L = P[:: len(P) // 20000], L[:: len(P) // 20000]
    beta = np.arctan(_reference_slopes(reference_surface, P))
    curvature = _reference_curvature(reference_surface)
    kappa = curvature(P)
    cam = dict(camera_xy_mm=camera_xy_mm, camera_height_mm=camera_height_mm)

    def residual(params):
        m = MeniscusModel(params[0], params[1], curvature=params[2], **cam)
        h = m.rise(beta, kappa)
        for _ in range(2):  # the slope and curvature where the contact point really is
            Q = m.unproject(P, h)
            h = m.rise(np.arctan(_reference_slopes(reference_surface, Q)), curvature(Q))
        return reference_surface.height(*m.unproject(P, h).T) - (L + h)

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
