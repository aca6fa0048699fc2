"""Faces that came out of the ink all at once: what the frames still say about them.

A face flatter than a level step per its width (a plateau, a tier's top) is under the ink
at one frame and wholly out at the next; no waterline crosses it, so first exposure has
nothing to interpolate and the thin plate would extrapolate into it from the rims and walls
around. These are the fit's priors for such faces: the bracket between the two levels and
its middle (flat_faces), a plane through the one level curve that crosses a tilted tier
(tilt_crossed_faces), the faces whose fit leaves its bracket, held at the middle
(flat_prior), and the nodes beside such a face that the fit ran away with (beside_faces).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..vision.types import signed_area
from .lattice import Lattice
from .slices import Slice, polyline_distance

# how far beyond a silhouette, as the camera saw it, a node was surely seen under the ink:
# a few pixels (rimrays.SEEN_TOL_MM is one) and the stage's play
SILHOUETTE_CLEAR_MM = 0.25


def flat_faces(
    lat: Lattice,
    slices: list[Slice],
    z_fe,
    first,
    far_mm: float,
    edge_mm: float = 0.0,
    seen: list[Slice] | None = None,
):
    """Heights for the nodes of faces that came out of the ink all at once.

    A face flatter than a level step per its width (a plateau, the top of a tier)
    is under the ink at one frame and wholly out at the next: no waterline crosses
    it, so first exposure has nothing to interpolate and the fit would extrapolate
    into it from whatever lies around - rims, walls - by millimetres of thin plate.
    What is sure is that it lies between the two levels. A node with no height yet
    gets that bracket when
    - it is clear of the frame above's waterline (that frame did not show it, and not
      by a hair): far_mm from it, or beside a rim put back, beyond the silhouette as
      the camera saw it (`seen`: _clear_of_frame_above);
    - and it is edge_mm from its own frame's waterline, unless that is a level curve
      (a corner the ink still filled inside the part) and no small loop
      (SMALL_LOOP_MM2): on the outline a node is on a rim, whose first exposure is
      not sure.
    If it is also farther than far_mm from its own frame's level curve, the middle
    of the bracket is its height. A cap above the highest frame gets neither unless a frame
    above showed nothing (its level then bounds the cap).
    -> (z_fe with the middle filled in, mask of those nodes, (lo, hi) per node: the
    bracket, NaN where none is sure)."""
    z = z_fe.copy()
    mask = np.zeros(lat.shape, bool)
    lo = np.full(lat.shape, np.nan)
    hi = np.full(lat.shape, np.nan)
    # not the lowest frame's nodes: with no frame below it, a level curve there that
    # stays put from the frame above (a sculptured top flattening out towards the rim)
    # cannot be told from a wall, and the nodes beside it would look like a flat face
    lowest = max(k for k, s in enumerate(slices) if not s.empty)
    todo = ~np.isfinite(z_fe) & (first < lowest) & (first > 0)
    if not todo.any():
        return z, mask, (lo, hi)
    X, Y = np.meshgrid(lat.x, lat.y)
    for k in np.unique(first[todo]):
        sel = todo & (first == k)
        q = np.column_stack([X[sel], Y[sel]])
        d_curve, _ = polyline_distance(slices[k].level_curve(), q)
        above = None if seen is None else seen[k - 1]
        clear = _clear_of_frame_above(slices[k - 1], above, q, far_mm)
        d_own, i_own = polyline_distance(slices[k], q)
        # near its own waterline only where that is a level curve, and not a small island's
        level = (d_curve <= d_own + 1e-9) & ~_small_loops(slices[k])[i_own]
        sure = clear & ((d_own > edge_mm) | level)
        idx = np.flatnonzero(sel.ravel())
        lo.ravel()[idx[sure]] = slices[k].level
        hi.ravel()[idx[sure]] = slices[k - 1].level
        mid = idx[sure & (d_curve > far_mm)]
        z.ravel()[mid] = 0.5 * (slices[k].level + slices[k - 1].level)
        mask.ravel()[mid] = True
    return z, mask, (lo, hi)


# a waterline loop smaller than this is a small island just out (or a pool about to close):
# the ink's meniscus holds it under to below its height (the crater's central boss, 13 mm²,
# came out 0.24 mm under its bracket), so its shore is no surer than a rim
SMALL_LOOP_MM2 = 50.0


def _small_loops(s: Slice) -> np.ndarray:
    """Per point (s.P stacks s.loops): whether its loop encloses less than SMALL_LOOP_MM2
    (either way round)."""
    small = np.array([abs(signed_area(lp)) < SMALL_LOOP_MM2 for lp in s.loops], bool)
    return np.repeat(small, [len(lp) for lp in s.loops])


def _clear_of_frame_above(above: Slice, above_seen: Slice | None, q, far_mm):
    """Nodes clear of the frame above's waterline: farther than far_mm from it (flat_faces).
    Where the nearest point is a silhouette put back on its rim, the waterline was hidden
    behind the face, between the rim and the silhouette as the camera saw it (`above_seen`,
    the same points before the rims were put back); a node beyond that silhouette by
    SILHOUETTE_CLEAR_MM, and far_mm from any waterline point, was seen under ink for sure,
    however near the rim (the blade's slab 2-3 mm past its hidden flank's crest stood
    1.5 mm high, unbracketed)."""
    d, i = polyline_distance(above, q)
    clear = d > far_mm
    if above.empty or above_seen is None or above.hidden is None or len(above_seen.P) != len(above.P):
        return clear
    sil = above.hidden[i] & ~clear
    if not sil.any():
        return clear
    waterline = above.P[~above.hidden]
    d_waterline = cKDTree(waterline).query(q[sil])[0] if len(waterline) else np.full(sil.sum(), np.inf)
    inside_seen, _ = polyline_distance(above_seen, q[sil], signed=True)
    clear[sil] = (d_waterline > far_mm) & (inside_seen < -SILHOUETTE_CLEAR_MM)
    return clear


def tilt_crossed_faces(lat: Lattice, slices: list[Slice], z, mask, first, far_mm):
    """Faces that came out at once on both sides of one level curve are one tilted face.

    A nearly flat tier tilted by less than a level step over its width comes out in two
    pieces: the part above level L (under at the level above) and the part below it (under
    at L), with the level curve at L between them and no other. Its middles would put it
    flat at two heights a step apart, with a step at the curve. What the frames say: the
    face crosses L along the curve, and it is a plane (to what two brackets can tell) whose
    slope keeps each piece inside its bracket out to its farthest node - at most
    step / distance. Half that slope, away from the curve on each side, is the middle of
    what they allow (a plane at the largest slope and a flat face at L are both possible),
    as the middle of the bracket is for a face no curve crosses. z (flat_faces' middles)
    is changed in place; -> mask of the nodes so placed."""
    K = len(slices)
    tilted = np.zeros(lat.shape, bool)
    X, Y = np.meshgrid(lat.x, lat.y)
    touch = far_mm + 2.0 * max(lat.hx, lat.hy)  # a piece ends this near the curve it meets
    for k in range(2, K):
        below, above = mask & (first == k), mask & (first == k - 1)
        curve = slices[k - 1].level_curve()
        if not below.any() or not above.any() or curve.empty:
            continue
        # the stretch of curve between the two pieces (elsewhere the curve may run along a
        # rim or a wall foot: it says nothing about this face's slope)
        nodes = [np.column_stack([X[m], Y[m]]) for m in (below, above)]
        near = [cKDTree(q).query(curve.P, distance_upper_bound=touch)[0] <= touch for q in nodes]
        is_shared = near[0] & near[1]
        shared = curve.P[is_shared]
        if len(shared) == 0:
            continue
        tree = cKDTree(shared)

        def to_stretch(q, curve=curve, is_shared=is_shared, tree=tree):
            # along the polyline where its nearest vertex is on the stretch, else to the stretch's points
            d, i = polyline_distance(curve, q)
            return np.where(is_shared[i], d, tree.query(q)[0])

        L = slices[k - 1].level
        steps = (L - slices[k].level, slices[k - 2].level - L)
        # the pieces on either side, and which piece of one side faces which of the other
        # across the shared stretch (each shared point: the pieces nearest it)
        sides = []
        for side, q in zip((below, above), nodes):
            labels, _ = ndimage.label(side)
            d = to_stretch(q)
            nearest = labels[side][cKDTree(q).query(shared)[1]]
            sides.append((np.flatnonzero(side.ravel()), labels[side], d, nearest))
        pairs = set(zip(sides[0][3].tolist(), sides[1][3].tolist()))
        for a in {p[0] for p in pairs}:
            partners = sorted({p[1] for p in pairs if p[0] == a})
            lo_on = sides[0][1] == a
            hi_on = np.isin(sides[1][1], partners)
            slope = 0.5 * min(steps[0] / sides[0][2][lo_on].max(), steps[1] / sides[1][2][hi_on].max())
            for sign, (idx, _, d, _), on in ((-1.0, sides[0], lo_on), (1.0, sides[1], hi_on)):
                z.ravel()[idx[on]] = L + sign * slope * d[on]
                tilted.ravel()[idx[on]] = True
    return tilted


def flat_prior(z, z_mid, mid, flat, tilted=None):
    """Mid-bracket heights for the faces that came out at once where the fit cannot place
    them: a face (a connected patch of such nodes) on which the fit leaves the bracket
    anywhere by more than a quarter of it has nothing to hold it (a plateau ringed by
    walls: the thin plate took it 20 mm up). Where the fit stays inside, a slope it
    continues from the waterlines around (a dome's corner between the last level
    curve and the rim) knows better than the middle - except on a face a single level
    curve crosses (`tilted`, tilt_crossed_faces): the thin plate bends it any way
    it likes at no cost, and the plane through that curve is all the frames tell.
    None when no face needs it."""
    if not mid.any():
        return None
    lo, hi = flat
    slack = 0.25 * (hi - lo)
    out = mid & ((z < lo - slack) | (z > hi + slack))
    if tilted is not None:
        out |= mid & tilted
    if not out.any():
        return None
    labels, _ = ndimage.label(mid)
    bad = np.isin(labels, np.unique(labels[out]))
    return np.where(bad, z_mid, np.nan)


def beside_faces(lat: Lattice, z, runaway, first, sure, bounds, reach_mm: float):
    """Nodes with no height of their own beside a face that came out at once, where the
    fit ran over their ceiling, take the nearest node of that face (one out in the same
    frame, within reach_mm, with a sure bracket), kept within their own bounds (lo, hi).

    Such a node is too near a rim or the frame above's waterline for a bracket of its own
    (flat_faces), and no waterline crossed it: the thin plate carries into it whatever
    slope lies beyond, and a fit over the node's ceiling says it did (the blade's plate,
    3.6 mm, stood 4.2-4.3 mm at its outline beyond the blade's tip and 5-8 mm beyond its
    hidden flank's foot: the fit there ran to 9.5 and was clipped). It came out of the ink
    with the face beside it, in the same frame; the face's height is the better guess.
    `runaway`: the nodes whose fit went over their ceiling and that have no height of
    their own. -> z with those nodes moved."""
    lo, hi = bounds
    pick = runaway & ~sure
    if not pick.any() or not sure.any():
        return z
    z = z.copy()
    X, Y = np.meshgrid(lat.x, lat.y)
    for k in np.unique(first[pick]):
        face = sure & (first == k)
        if not face.any():
            continue
        nodes = np.flatnonzero((pick & (first == k)).ravel())
        q = np.column_stack([X.ravel()[nodes], Y.ravel()[nodes]])
        d, i = cKDTree(np.column_stack([X[face], Y[face]])).query(q)
        close = d <= reach_mm
        near = nodes[close]
        z.ravel()[near] = np.clip(z[face][i[close]], lo.ravel()[near], hi.ravel()[near])
    return z
