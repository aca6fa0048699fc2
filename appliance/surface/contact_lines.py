"""The top from its contact lines: the meniscus correction of the fit.

The contact line at free-surface level L is where top - h(beta) = L, beta the top's own
slope there. So the contact lines are exactly the level curves of the apparent surface
    A = top - h(atan |grad top|),
which the ordinary fit reconstructs from them as if they were waterlines (first exposure,
thin plate, cross-validated smoothing: nothing about the meniscus). The top then solves
    top - h(atan |grad top|) = A
node by node: a first-order equation, solved as least squares with a little smoothness
on the rise phi = top - A (third-order, so it bends phi only where its curvature changes;
where the top is level, on the top itself: LevelRows) by damped Gauss-Newton
(Levenberg-Marquardt; h(|grad|) linearised along the slope).

Why not the obvious iteration (rise from the current fit's slope, refit, repeat)? Where
the top is flat it runs away: raising a contact line steepens the fit's drop beside it,
which raises the line more. Sample 4's flat corner went from slope 0.12 to 2.3 and 2.4 mm
too high; elsewhere it took eight fits to settle (sample 1: 0.027 mm after two, 0.011 after
eight). And why in steps, on every second node first? Where the top is flat the equation
has near-solutions with bumps on it: a bump phi = K exp(-r / l_c) keeps its contact line at
its foot, so the data never see it, and Gauss-Newton started far away falls into one
(sample 4's corner: 2.6 mm). Turning the meniscus on in steps keeps the solution on the
branch that starts at top = A; the coarse lattice makes the steps cheap and needs a
smoothness length of three of its spacings (central differences leave grid-scale modes
free); the full lattice then takes three steps from the coarse answer with one spacing.
Three, not until it settles (FINE_ITERATIONS): the equation differentiates the frames' noise,
and the later steps fit it. On rendered physics scans of samples 2/3/4 three steps gave Ea
0.014/0.023/0.039 mm, five 0.043/0.025/0.047, eight 0.045/0.038/0.046; on the exact
apparent surfaces of the tests below eight are better (a dome 0.0068 -> 0.0012 mm), which
is the price of stopping early.
The apparent surface's outline nodes are not trusted (RIM_UNTRUSTED): where the top rises
to a rim, errors there travel inwards (sample 4's rims: 0.22 -> 0.03 mm on the lattice).
On exact apparent surfaces (a dome, sample 4's saddle) this recovers the top to 0.005 and
0.004 mm mean (tests/test_surface_physics.py).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.linalg import splu

from .dewetted import depression_depth
from .gridfit import FitProblem
from .lattice import Lattice, bilinear, fill_nearest, steepness
from .meniscus import CURVATURE_STEP_MM, MeniscusModel, level_curve_curvature
from .sharp_edges import rows_not_over, slope_range_near_walls, slopes_held_at_edges

SOLVE_MAX_SIDE = 101  # the rise is smooth: solved on at most this many nodes a side
FINE_ITERATIONS = 3  # Levenberg-Marquardt steps on the full solve lattice
RIM_UNTRUSTED = 2  # nodes next to the outline whose apparent height the solve ignores
LEVEL_SLOPE = 0.15  # slopes (rise over run) round which the rise's V is the top's, not phi's
RUNAWAY_BAND = 3  # nodes inside the trusted outline where the level solve may run away
RUNAWAY_MM = 0.2  # how far above the plain solve it must stand there to count as running away
BEND_SLOPE = 2 * LEVEL_SLOPE  # flatter, the top's level curves' bend is held to the seen one


def top_from_apparent(
    lat, apparent, footprint, model: MeniscusModel, faces=None, ceiling=np.inf, exposed=None
):
    """-> the top (NaN where `apparent` is) whose contact lines are the level curves of
    `apparent` (the fit of the contact lines as they were seen, on lattice `lat`).
    `faces`: nodes of faces that came out at once (dewetted_nodes). No contact line crossed
    them, so no line's bend changes their depression: there the curvature term is left out
    (else the fit's ripples on a flat face, divided by CURVATURE_FLAT, read as bends: the
    steep front's apron came out 0.18 mm high).
    `ceiling`: the highest the top can stand (summit.summit_ceiling), held at every step, so
    that the rise on the flanks follows a crest held under it (the harsh ring: interior p99
    0.326 mm with the top clamped after the solve, 0.207 held during it).
    `exposed`: the first-exposure heights the fit was given (NaN where none, and where a face
    hid the node): where the fit rings beside a wall they still show a face level up to its
    edge (sharp_edges.py).

    Where the top is level the solve smooths the top, not the rise (LevelRows). That leaves
    free a mode of top - h(|grad top|) = A that grows as exp(d / (l_c cos(theta / 2))) towards
    the outline, where the untrusted rim holds nothing down: on a level shelf at the outline
    (the harsh plateau's 10 mm shelf, its apparent surface flat at 9.96) a bump in A a few
    millimetres in set it off and the top climbed 10.1 -> 12.5 over the last eight nodes. The
    rise smoothed everywhere (`plain`) has no such mode. So where, within RUNAWAY_BAND nodes
    of the trusted outline, the level solve stands more than RUNAWAY_MM above a level plain
    one, the top is solved again held to the plain one there (a data-weight tie): the mode needs
    the rim to grow into, and tied there it cannot start. The tied solve is the top, but in the
    band, where the plain solve is level, the lower of it and the level solve: the tie moves the
    whole top and can set the mode off where the level solve had none."""
    top = _top_from_apparent(lat, apparent, footprint, model, faces, ceiling, exposed=exposed)
    k = _solve_stride(lat)
    rim = footprint & ~ndimage.binary_erosion(
        footprint, iterations=k * (RIM_UNTRUSTED + RUNAWAY_BAND), border_value=0
    )
    # a rise the apparent surface's own slope cannot explain, by half of it again, is the
    # runaway's mark (on a crest or a slope the top's slope is at most A's, and so is its
    # rise): only then are the plain solve and the tied one worth their time (processing the
    # harsh plateau: 20 -> 34 s). Half of |h|: an ink that dewets has h < 0 on level faces,
    # where 1.5 h stood below h itself and every one of its scans was solved three times
    g_a = steepness(lat, apparent)
    h_a = model.rise_on_slope(g_a)
    unexplained = np.nan_to_num(top - apparent) - (h_a + 0.5 * np.abs(h_a))
    if not (rim & (g_a < 2 * LEVEL_SLOPE) & (unexplained > RUNAWAY_MM)).any():
        return top
    plain = _top_from_apparent(
        lat, apparent, footprint, model, faces, ceiling, level_rows=False, exposed=exposed
    )
    # the mode grows out of a level top: where the plain solve is level (on a wall the two
    # solves' rises differ for other reasons: sample 4's walls, all within its rim band)
    level_plain = steepness(lat, plain) < 2 * LEVEL_SLOPE
    high = (np.nan_to_num(top - plain) > RUNAWAY_MM) & level_plain
    ran = rim & ndimage.binary_dilation(high, iterations=k)
    if not ran.any():
        return top
    tied = _top_from_apparent(
        lat, apparent, footprint, model, faces, ceiling, anchor=(ran, plain), exposed=exposed
    )
    # the mode only lifts the top (the blade's 4 mm strip of slab between its end's taper and
    # the outline, second ink: 0.2 mm high from the level solve, 0.4-1.2 mm from the tied one)
    return np.where(rim & level_plain, np.fmin(tied, top), tied)


def _solve_stride(lat) -> int:
    """Every how many of `lat`'s nodes the solve takes one (at most SOLVE_MAX_SIDE a side)."""
    return max(1, int(np.ceil(max(lat.shape) / SOLVE_MAX_SIDE)))


def _top_from_apparent(
    lat, apparent, footprint, model, faces=None, ceiling=np.inf, level_rows=True, anchor=None, exposed=None
):
    """top_from_apparent's solve: coarse, then fine. `level_rows`: smooth the top where it is
    level (LevelRows), else the rise everywhere. `anchor`: (nodes, top) to hold the solve to."""
    k = _solve_stride(lat)
    sub = Lattice(lat.x[::k], lat.y[::k])
    A = fill_nearest(apparent)[::k, ::k]
    exposed = None if exposed is None else exposed[::k, ::k]
    fp = footprint[::k, ::k]
    if fp.sum() < 9:
        return apparent
    h = max(sub.hx, sub.hy)
    straight = None if faces is None else faces[::k, ::k]
    kappa = contact_line_curvature(sub, A, fp, _holds_bends(model)) if model.curvature else None
    if anchor is not None:
        anchor = (np.asarray(anchor[0], float)[::k, ::k], np.nan_to_num(anchor[1])[::k, ::k])
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
            ceiling=ceiling,
            level_rows=level_rows,
            anchor=None if anchor is None else (anchor[0][::2, ::2], anchor[1][::2, ::2]),
            exposed=None if exposed is None else exposed[::2, ::2],
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
            ceiling=ceiling,
            level_rows=level_rows,
            anchor=anchor,
            exposed=exposed,
        )
    else:
        top = _solve_top(
            sub,
            A,
            fp,
            model,
            3 * h,
            A,
            steps=(0.5, 1.0),
            iterations=5,
            kappa=kappa,
            straight=straight,
            ceiling=ceiling,
            level_rows=level_rows,
            anchor=anchor,
            exposed=exposed,
        )
    rise = top - A if k == 1 else _resample_rise(top - A, sub, lat)
    return np.where(np.isfinite(apparent), apparent + rise, np.nan)


def contact_line_curvature(lat, top, footprint=None, along_on_flats=False):
    """The contact lines' own curvature (1/mm) at every node: that of the top's level curves,
    taken on a CURVATURE_STEP_MM grid (bicubic from the lattice) so that a crest's clipped
    spike is as narrow as it really is, whatever the lattice's spacing.
    `footprint`: the part's nodes. The millimetre the bend is averaged over is then that of
    the top the solve trusts: not the nodes off the part, whose nearest-filled heights turn
    the level curves to meet the outline square (a bend no contact line has), nor the rim
    (RIM_UNTRUSTED), whose heights are the smoothness' continuation, not data. Averaged
    over both, a plane came out 0.16 mm off (its straight contact lines read as bent), and
    sample 4 (10 mm, all within a millimetre or two of its outline) 0.13 mm off on the
    solve's lattice from the renderer's exact apparent surface.
    `along_on_flats`: on nearly level nodes, the bend along the level curves alone
    (meniscus.level_curve_curvature)."""
    ky = max(1, int(np.ceil(lat.hy / CURVATURE_STEP_MM)))
    kx = max(1, int(np.ceil(lat.hx / CURVATURE_STEP_MM)))
    fj = np.arange((top.shape[0] - 1) * ky + 1) / ky
    fi = np.arange((top.shape[1] - 1) * kx + 1) / kx
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    fine = ndimage.map_coordinates(top, [FJ, FI], order=3, mode="nearest")  # C2: curvature needs it
    known = None
    if footprint is not None:
        inner = ndimage.binary_erosion(footprint, iterations=RIM_UNTRUSTED, border_value=0)
        known = ndimage.map_coordinates(inner.astype(float), [FJ, FI], order=0, mode="nearest") > 0.5
    bend = level_curve_curvature(fine, lat.hy / ky, lat.hx / kx, known=known, along_on_flats=along_on_flats)
    return bend[::ky, ::kx]


def _resample_rise(phi, src, dst):
    """A rise field (NaN off its unknowns) read on another lattice, bicubic."""
    fi = (dst.x - src.x[0]) / src.hx
    fj = (dst.y - src.y[0]) / src.hy
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    return ndimage.map_coordinates(fill_nearest(phi), [FJ, FI], order=3, mode="nearest")


def _solve_top(
    lat,
    A,
    footprint,
    model,
    length_mm,
    start,
    steps,
    iterations,
    tol=1e-7,
    kappa=None,
    straight=None,
    ceiling=np.inf,
    level_rows=True,
    anchor=None,
    exposed=None,
):
    """Levenberg-Marquardt on |top - h(|grad top|) - A|^2 (footprint nodes) + lam |phi|^2_R3,
    the capillary length turned on in `steps` (fractions of it)."""
    problem = FitProblem(lat, footprint)
    act = problem.active
    # the apparent surface's outline nodes are the fit's least sure (their first exposure
    # comes from the wall's waterline, a level step wide): where the top rises to a rim the
    # equation carries their error inwards, so there the top is the smoothness' continuation
    trusted = ndimage.binary_erosion(footprint, iterations=RIM_UNTRUSTED, border_value=0)
    if trusted.sum() < 9:
        trusted = footprint
    Dx, Dy, (ox, oy), edges = slopes_held_at_edges(problem, A, trusted, LEVEL_SLOPE, exposed)
    rows = rows_not_over(problem.third_order_rows(), edges)
    R = (rows.T @ rows).tocsc()
    lam = length_mm**6 / (lat.hx * lat.hy)
    a, on = A[act], trusted[act].astype(float)
    level = LevelRows(rows, on, straight if straight is None else straight[act]) if level_rows else None
    if anchor is not None:
        w_anchor, top_anchor = anchor[0][act], anchor[1][act]
    else:
        w_anchor, top_anchor = np.zeros(problem.n), np.zeros(problem.n)
    of_a = rows @ a
    target = of_a  # smoothing phi = top - A: the top's third differences are to follow A's
    I = sp.identity(problem.n, format="csc")
    t = np.minimum(start[act].astype(float), ceiling)
    curved = kappa is not None

    keep = 1.0 if straight is None else (~straight[act]).astype(float)

    seen_bend = kappa[act] * keep if curved else None
    held = _holds_bends(model)  # only a depression feeds a bump's bend back (believed_bend)

    def curvature_of(t, g):
        """The contact lines' curvature where the top is t (slope g): that of its level curves,
        as far as the contact lines seen show it where the top is nearly level (believed_bend)."""
        full = np.full(lat.shape, np.nan)
        full[act] = t
        own = contact_line_curvature(lat, fill_nearest(full), footprint, held)[act] * keep
        return believed_bend(own, seen_bend, g) if held else own

    kap = seen_bend

    g_a = np.hypot(Dx @ a + ox, Dy @ a + oy)
    lo, hi = slope_range_near_walls(lat, A, footprint, act, g_a, RIM_UNTRUSTED + RUNAWAY_BAND)

    def objective(t, m):
        g = np.clip(np.hypot(Dx @ t + ox, Dy @ t + oy), lo, hi)
        r = on * (t - m.rise_on_slope(g, kap) - a)
        p = rows @ t - target
        q = np.sqrt(w_anchor) * (t - top_anchor)
        return float(r @ r + lam * (p @ p) + q @ q)

    mu = 1.0
    for f in steps:
        m = model.scaled(f)
        for _ in range(iterations):
            gx, gy = Dx @ t + ox, Dy @ t + oy
            g = np.hypot(gx, gy)
            if curved:
                kap = curvature_of(t, g)
            if level is not None:
                target = level.target(of_a, g, t < ceiling)
            read = np.clip(g, lo, hi)  # slope_range_near_walls
            r = on * (t - m.rise_on_slope(read, kap) - a)
            clipped = (g < lo) | (g > hi)  # the rise does not follow the slope there
            dh = np.where(clipped, 0.0, m.rise_on_slope_derivative(read, kap))
            c = dh / np.sqrt(g * g + 1e-6)  # dh/d(grad) = h' grad / |grad|
            J = sp.diags(on) @ (I - sp.diags(c * gx) @ Dx - sp.diags(c * gy) @ Dy)
            M = (J.T @ J + lam * R + sp.diags(w_anchor)).tocsc()
            rhs = -(J.T @ r) - lam * (rows.T @ (rows @ t - target)) - w_anchor * (t - top_anchor)
            f0 = objective(t, m)
            for _ in range(8):
                step = splu((M + mu * I).tocsc(), permc_spec="COLAMD").solve(rhs)
                if objective(t + step, m) < f0:
                    t, mu = np.minimum(t + step, ceiling), max(mu / 3.0, 1e-8)
                    break
                mu *= 4.0
            else:
                break  # no step lowers it: as good as it gets
            if np.max(np.abs(step)) < tol:
                break
    out = np.full(lat.shape, np.nan)
    out[act] = t
    return out


def _holds_bends(model) -> bool:
    """Whether the solve's bends are held (believed_bend) and taken along the level curves
    alone where the top is level (level_curve_curvature's `along_on_flats`): for an ink that
    dewets. For one that wets, h(0) = 0, so a level face's bend changes nothing there."""
    return depression_depth(model) > 0


def believed_bend(own, seen, slope):
    """The bend (1/mm) the solve gives a contact line: `own`, that of the top's level curves,
    except where the top is flatter than BEND_SLOPE. A level curve's bend is a second
    derivative over the first, so where the top is nearly level a ripple of the solve reads as
    a bend, and the bend feeds back: a bump of the top bends its level curves round it, which
    lowers the depression there, which raises the bump. Only an ink that dewets has a
    depression on level faces (dewetted.depression_depth): for one that wets, h(0) = 0 and the
    bend changes nothing there. On the held-out plateau (second ink) the top 3-8 mm inside its
    25 mm rim rose into a lip 0.4-0.8 mm high, its level curves bent by 0.42-0.44/mm where the
    renderer's top has 0-0.1. There the bend is believed only as far as the contact lines as
    seen show it (`seen`: the apparent surface's level curves, which are the contact lines):
    the smaller of the two, none where they disagree in sign."""
    same = np.sign(own) == np.sign(seen)
    limited = np.where(same, np.sign(own) * np.minimum(np.abs(own), np.abs(seen)), 0.0)
    return np.where(slope < BEND_SLOPE, limited, own)


class LevelRows:
    """Which smoothness rows smooth the top itself rather than the rise phi = top - A.

    The rise h(|grad top|) has a V where the top is level (a crest, a floor, a saddle's
    centre): dh/d|grad| = l_c cos(theta / 2) there, 2.2 mm for the second ink, so phi is
    kinked while the top is smooth, and smoothing phi rounds the V off (the crater's crest
    came out 0.21 mm high, its floor 0.38). A row with a node flatter than about
    LEVEL_SLOPE smooths the top instead; one that reaches the untrusted outline nodes (their
    heights are the smoothness' alone) keeps smoothing phi, which continues the rise there.
    So do faces that came out at once (`faces`): no contact line crossed them, their rise is
    the flat depression, with no V (a 6 mm face under the second ink came out 0.10 mm high
    with the top smoothed there), and nodes a summit's ceiling holds (summit.py): level
    because they are held, not a crest the contact lines went round (a mesa's shoulder
    came out 1.3 mm off with the top smoothed there).
    It has a price on the first ink's seed-table scans (benches/seed_table.py --effects
    physics, same renders, without -> with): sample 3 0.0236 -> 0.0258 mm (it loses along its
    left rim, x < 6 mm, where the top stands 44-46 mm beside the block's wall, more than it
    gains on the rest) and sample 4 0.0281 -> 0.0300 (its near-flat strip and the 0.5 mm
    inside its outline). Neither a sharper switch (the slope's fourth or eighth power) nor
    keeping phi within 1.5-4 mm of the outline wins both back."""

    def __init__(self, rows, trusted, faces=None):
        self.crossed = 1.0 if faces is None else (~faces).astype(float)
        self.reach = abs(rows).tocsr()
        self.reach.data[:] = 1.0  # the nodes each row touches
        self.inside = (self.reach @ (1.0 - trusted)) == 0

    def target(self, of_a, g, free=True):
        """-> what the rows applied to the top should be: those applied to A (`of_a`) where
        the top slopes (phi smooth), 0 where it is level (the top smooth); g: |grad top|."""
        w = self.crossed * free / (1.0 + (g / LEVEL_SLOPE) ** 2)
        level = np.asarray(self.reach.multiply(w[None, :]).max(axis=1).todense()).ravel()
        return of_a * (1.0 - level * self.inside)


def contact_points(slices, lat, rise, model: MeniscusModel):
    """The contact lines' points where they really are, from a rise field on `lat`
    -> (slices at the liquid's level for the apparent surface's fit, slices at
    level + rise for the rest). A point standing h above the ink is seen displaced
    by the perspective (MeniscusModel.unproject); wall points stay as they are (a
    wall is seen by its top edge, put back by perspective.unproject_rims)."""
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
        P = model.unproject(s.P, h, s.sight_mm)
        flat.append(s.moved(P, s.z))
        raised.append(s.moved(P, s.z + h))
    return flat, raised
