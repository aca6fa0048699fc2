"""One pass of the fit: first exposure, the priors, the regularised fit, the meniscus.

fit_pass places the lattice nodes from the waterlines (exposure.py), adds the priors for
faces no waterline crossed (flatfaces.py) and, with a meniscus, the dewetted faces'
brackets (dewetted.py); it solves the thin-plate fit (gridfit.py) with its smoothing
length cross-validated on held-out nodes, and with a meniscus takes that fit for the
apparent surface and solves the top from it (contact_lines.py). bracket holds the nodes
the fit extrapolated into between the levels that saw them come out.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import SettingError
from ..forks import each_in_parts
from .contact_lines import contact_points, top_from_apparent
from .dewetted import bracket_dewetted_faces, dewetted_nodes, pinned_rims_as_walls, place_dewetted_faces
from .exposure import first_exposure
from .flatfaces import flat_faces, flat_prior, tilt_crossed_faces
from .gridfit import FitProblem, point_data
from .inkbounds import behind_faces
from .summit import summit_ceiling

BRACKET_SLACK_LEVELS = 2  # one held sample 4's rim nodes 1.4 mm low (clean Ea 0.0220 -> 0.0174 with two)


def bracket(z, first, slices, rise_max=0.0, sink=0.0):
    """Clamp each node between the level where it came out and the one above it
    (bracket_bounds)."""
    lo, hi = bracket_bounds(first, slices, rise_max, sink)
    return np.clip(z, lo, hi)


def bracket_bounds(first, slices, rise_max=0.0, sink=0.0, slack=BRACKET_SLACK_LEVELS):
    """Per node, (lo, hi): the level where it came out and the one above it.

    A node exposed first at frame k and still under at frame k - 1 lies in
    between, whatever the fit's smoothness would rather do (extrapolating into
    a gap beside a wall, say). Meniscus-corrected heights widen the bracket, and
    with a meniscus a node may stand up to its largest rise above the level that
    still covered it (`rise_max`): the ink climbs a rim and keeps it under (sample
    4's 39 mm summit rim, exposed at 36 mm, was clamped there, 3 mm low). An ink that
    dewets leaves a flat face up to its depression (`sink`) above it, so a node may
    also stand that far below the level that exposed it (the steep front's apron, out at
    5.4 mm and 4.0-4.4 mm high, was clamped up to 4.6-5.1 where no contact line crossed).
    """
    K = len(slices)
    top = next(k for k, s in enumerate(slices) if not s.empty)
    # the rises of the level-curve points (a wall point's says nothing about the top)
    curves = [s.level_curve() if not s.empty else s for s in slices]
    lo_rise = [float(np.min(c.z - c.level)) if not c.empty else 0.0 for c in curves]
    hi_rise = [float(np.max(c.z - c.level)) if not c.empty else 0.0 for c in curves]
    lv = np.array([s.level for s in slices] + [-np.inf])
    lo = np.array([lv[k] + min(lo_rise[k], 0.0) - sink for k in range(K)] + [-np.inf])
    hi = np.array([np.inf] + [lv[k - 1] + max(hi_rise[k - 1], rise_max, 0.0) for k in range(1, K)] + [np.inf])
    hi[top] = np.inf
    # BRACKET_SLACK_LEVELS of slack each way: where waterlines crowd (a saddle's corner, a
    # face rising at 8 to a rim) the side of a node is not sure; the bracket is there to stop
    # wild extrapolation, not to fine-tune
    n = slack
    lo_s = np.r_[lo[n:], [-np.inf] * n]
    hi_s = np.r_[[np.inf] * n, hi[: K + 1 - n]]
    hi_s[K] = np.inf  # never exposed (nodes on the outline itself): no bracket
    return lo_s[first], hi_s[first]


HOLD_SLACK_LEVELS = 1  # how far past its bracket the fit may carry a node that has a height:
HOLD_MARGIN_MM = 0.5  # a level, and at least this (refinement frames 0.06 mm apart: sample 2's
# second-ink fit, held to a level's slack there, went 0.047 -> 0.053 mm)


def held_to_data(z, placed, first, slices, slack=HOLD_SLACK_LEVELS, margin=HOLD_MARGIN_MM):
    """The fit, except where it leaves the bracket of a node that has a height of its own
    (first exposure): there that height. The thin plate cannot turn a wall's foot: beside a
    12 mm boss it carried the nodes 0.3 mm off the wall 2.5 mm up on average, their own
    heights right. Not a height the first exposure clamped to a level of its bracket (its
    polynomial left it): that is a bound, not a height (the blade's nodes beside its crest)."""
    lo, hi = bracket_bounds(first, slices, slack=slack)
    lo0, hi0 = bracket_bounds(first, slices, slack=0)
    lo, hi = np.minimum(lo, lo0 - margin), np.maximum(hi, hi0 + margin)
    levels = np.round([s.level for s in slices], 9)
    at_level = np.isin(np.round(np.nan_to_num(placed, nan=np.inf), 9), levels)
    off = np.isfinite(placed) & ~at_level & ((z < lo) | (z > hi))
    return np.where(off, placed, z)


def _fit_nodes(problem, z_nodes, pts, zp, length_mm, point_weight, prior=None):
    """The regularised fit; `prior` (NaN where none): node heights for the faces nothing
    else places (faces that came out at once: flatfaces.flat_prior)."""
    lat = problem.lat
    lam = length_mm**4 / (lat.hx * lat.hy)  # data are one per node: density 1 / cell area
    blocks = [problem.node_rows(z_nodes, 1.0)]
    if point_weight > 0 and len(pts):
        blocks.append(problem.data_rows(pts, zp, point_weight))
    start = z_nodes
    if prior is not None:
        blocks.append(problem.node_rows(prior, FLAT_PRIOR_WEIGHT))
        start = np.where(np.isfinite(z_nodes), z_nodes, prior)
    return problem.solve(blocks, lam, start=start)


def _cross_validate(problem, z_fe, pts, zp, point_weight, seed=0):
    """Hold out a tenth of the first-exposure nodes, fit on the rest, score on them."""
    rng = np.random.default_rng(seed)
    have = np.flatnonzero(np.isfinite(z_fe.ravel()) & problem.active.ravel())
    if have.size < 50:
        return None, []
    held = rng.choice(have, size=max(5, have.size // 10), replace=False)
    train = z_fe.copy()
    train.ravel()[held] = np.nan
    lengths = min(problem.lat.hx, problem.lat.hy) * np.array([0.5, 1, 2, 4])

    def score(i):
        z = _fit_nodes(problem, train, pts, zp, lengths[i], point_weight)
        r = z.ravel()[held] - z_fe.ravel()[held]
        return float(lengths[i]), float(np.sqrt(np.mean(r**2)))

    # four fits that need nothing of each other: on the cores where forking is allowed
    curve = each_in_parts(score, np.ones(lengths.size))
    best = min(curve, key=lambda c: c[1])[0]
    return best, curve


FLAT_FAR_NODES = 3  # lattice spacings from any waterline: a node on a face that came out at once,
FLAT_FAR_MM = 2.0  # and at least this far (a small part's fine lattice: sample 4's waterlines
# a node or two apart on its 20 mm rims would take its faces for flat)
FLAT_EDGE_MM = 0.5  # nor on the outline: sample 4's rim nodes first come out levels late
FLAT_PRIOR_WEIGHT = 1.0  # such a node's mid-bracket height, as a first-exposure height weighs


def flat_far_mm(lat) -> float:
    """How far from the frame above's waterline a node must be to be on a face that came out at once."""
    return max(FLAT_FAR_NODES * max(lat.hx, lat.hy), FLAT_FAR_MM)


def flat_face_rise(model, flat, far_mm):
    """The most the ink can climb a face that came out at once (0 where no meniscus): its
    apparent height stays within its bracket over the far_mm or more it lies from the
    frame above's waterline, so it is no steeper than the bracket over that. (The
    steepest rise of all, a wall's, let the shoulder's rise carry the plateau's foot
    0.3-0.65 mm above its 10 mm base on the harsh bench.) Below zero for an ink that
    dewets a face that flat: the frame above's ink, which still covered the face, stood
    at least that far above it (the second ink's blade: the slab beside its flank's foot)."""
    lo, hi = flat
    if model is None:
        return np.zeros(lo.shape)
    return model.rise(np.arctan(np.nan_to_num(hi - lo) / far_mm))


class PassResult(NamedTuple):
    """What a pass of the fit leaves for the next one and for the output."""

    z: np.ndarray  # the top on the lattice
    z_fe: np.ndarray  # first-exposure heights (of the contact lines; NaN where none)
    first: np.ndarray  # the frame each node came out in (len(slices): never)
    footprint: np.ndarray  # nodes over the part
    slices: list  # the slices at their heights (level + rise with a meniscus)
    length: float  # the smoothing length used
    curve: list | None  # cross-validation (length, score) pairs, when it ran
    rise: np.ndarray | None  # the meniscus' rise on the lattice (None without one)
    flat: tuple  # (lo, hi) bracket per node of the faces that came out at once


def fit_pass(lat, slices, opt, ftol, length, rise, seen=None):
    """First exposure and the fit (smoothing cross-validated on the first pass). With a
    meniscus the fit is of the contact lines - where the last pass's rise field says they
    really are - and the top is solved from it (contact_lines.top_from_apparent). `seen`:
    the slices as the camera saw them, silhouettes and all (none: no face hid anything)
    -> PassResult."""
    if opt.meniscus is not None:
        slices = pinned_rims_as_walls(slices, opt.meniscus, opt.wall_tol_mm)
    observed = slices
    if opt.meniscus is not None and rise is not None:
        slices, _ = contact_points(observed, lat, rise, opt.meniscus)
    z_fe, first, footprint = first_exposure(lat, slices, ftol)
    # a node a face hid has no height of its own: the fit places it, between the level it
    # was out at and the ray over the face's edge (reconstruct's node bounds). Nor is it on a
    # face that came out at once: the level it came out at is the part's beyond the face's
    # foot (the blade's flank behind its crest, 20.7 mm high, was held at 4.7 in the plate's
    # bracket), so the dewetted faces are sought among the nodes in sight
    hidden = behind_faces(lat, seen, slices, first) if seen is not None else np.zeros(lat.shape, bool)
    in_sight = footprint & ~hidden
    placed = z_fe
    if opt.meniscus is not None:
        placed = place_dewetted_faces(lat, z_fe, first, in_sight, slices, opt.meniscus)
    placed = np.where(hidden, np.nan, placed)
    h = max(lat.hx, lat.hy)
    z_mid, mid, flat = flat_faces(lat, slices, z_fe, first, flat_far_mm(lat), max(2 * h, FLAT_EDGE_MM), seen)
    tilted = tilt_crossed_faces(lat, slices, z_mid, mid, first, flat_far_mm(lat))
    if not footprint.any():
        raise SettingError("grid", "the grid does not cover the part: no node is inside any waterline")
    problem = FitProblem(lat, footprint)
    pts, zp = point_data(slices, 0.5 * min(lat.hx, lat.hy))
    curve = None
    if length is None:
        length, curve = _cross_validate(problem, placed, pts, zp, opt.point_weight)
        if length is None:
            length = min(lat.hx, lat.hy)
    z = _fit_nodes(problem, placed, pts, zp, length, opt.point_weight)
    prior = flat_prior(z, z_mid, mid & ~np.isfinite(placed), flat, tilted)
    if prior is not None:
        z = _fit_nodes(problem, placed, pts, zp, length, opt.point_weight, prior)
    z = held_to_data(z, placed, first, slices)
    ceiling = summit_ceiling(observed, opt.meniscus)
    if opt.meniscus is None:
        z = np.minimum(z, ceiling)
    else:
        z = bracket_dewetted_faces(lat, z, z_fe, first, in_sight, slices, opt.meniscus)
        faces = dewetted_nodes(lat, z_fe, first, in_sight, slices, opt.meniscus)
        # `placed`, not z_fe: a node a face hid came out with the part beyond the face's foot, so
        # z_fe shows the face below level right up to the wall, and the edge is sought there (the
        # steps' base 1-3 mm short of the hidden strip stood 0.6-1.4 mm high)
        top = top_from_apparent(lat, z, footprint, opt.meniscus, faces, ceiling, exposed=placed)
        top = np.minimum(top, ceiling)
        rise = top - z
        z = top
        _, slices = contact_points(observed, lat, rise, opt.meniscus)
    return PassResult(z, z_fe, first, footprint, slices, length, curve, rise, flat)
