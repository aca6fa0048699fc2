"""How each height-map cell was obtained, and how far it may be off (mm).

A height map is not equally sure everywhere. A cell on a waterline the camera
saw is pinned to within the waterline's own error; a cell between two
waterlines is interpolated across the gap; a cell above the highest frame that
showed the part is extrapolated; a cell on a wall or under an occluding face
only has the edge above it; a cell clamped to the base plane or filled from its
neighbours had no good height at all. The source says which, and the
uncertainty (one number in mm per cell, about one standard deviation) is built
from what limits each:

- lateral: the waterline is placed to about half a pixel (how closely the fit's
  lattice follows it is the fit's residual, below); on a slope s a lateral error dx is
  a height error s dx (a steep face or a wall is uncertain, a flat top is not);
- gap: between waterlines the surface is continued from the curves around it;
  the further from the nearest seen waterline (d) and the more the surface bends
  (curvature k), the more that continuation can miss: k d^2 / 2, never more than
  the frames' own bracket (the level step: the cell came out of the ink between
  two levels, a step apart);
- extrapolation above the top frame: the part's top lies between the highest
  level that showed it and the one above that did not; the further in from the
  top waterline, the more of that step is unknown (in proportion to how far in
  the top region reaches: a cap's radius, a ridge's half-width);
- disagreement: the fit's residual at the waterline points near the cell (and
  against the cell's own first exposure, up to a step), and frames that
  contradict each other or the fit (exposure is monotone: a point out of the ink at one
  level is out at every lower one; a cell seen out, then under, then out again
  came from a transient bright thing or a misread frame; when the fit stands
  above the level where the cell was still under, it is off by that much; and
  the frame just before a cell's first exposure still covered it, so a fit
  standing above that level by more than the meniscus rise applied there rests
  on nothing the frames showed, and is unsure by the excess);
- the meniscus: its correction models a contact line on an open face; near the
  outline the ink also meets the part's edge, within about a capillary length,
  so the correction there is unsure by its size times exp(-distance / length).
  The same holds where the face does not stay open: within a capillary length of a
  face whose rise differs (a wall beside a shelf, the two flanks of a crest) the
  meniscus is shared between them, unsure by a share of the difference; and within
  a capillary length below the top of the piece it came out with, the face ends
  before the ink can climb the rise the model gives it (a crest, a plateau's rim).

`DEFAULT_UNCERTAIN_MM` is the threshold above which a cell counts as low
confidence: the G-code header lists such regions and the report names them
(`confidence.py`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .lattice import Lattice, bilinear, fill_nearest
from .slices import level_step, polyline_distance

# the sources, in the order of their codes (HeightMap.source holds the codes)
SOURCES = ("seen", "interpolated", "extrapolated", "occluded", "wall", "clamped", "filled", "held")
SEEN, INTERPOLATED, EXTRAPOLATED, OCCLUDED, WALL, CLAMPED, FILLED, HELD = range(len(SOURCES))
NO_SOURCE = -1  # off the part, or a map that does not say

DEFAULT_UNCERTAIN_MM = 0.1  # cells above this are low confidence (G-code header, report)
LATERAL_PX = 0.5  # a waterline is placed to about half a pixel
FAR_GAPS = 4.0  # this many times the part's typical distance to a waterline: unpinned
STEEP_SLOPE = 3.0  # |grad z| above this (72 deg) the cell is on a wall
RISE_SHARE = 0.1  # where its face is cut short or shared, a meniscus rise is unsure by this share


def source_code(name: str) -> int:
    return SOURCES.index(name)


@dataclass
class CellEvidence:
    """What the lattice fit knows per node, the inputs of `node_uncertainty`."""

    lat: Lattice
    z: np.ndarray  # the fitted heights (NaN off the part)
    z_fe: np.ndarray  # first-exposure heights (NaN where the fit filled in)
    first: np.ndarray  # index of the level where each node came out of the ink
    footprint: np.ndarray
    slices: list  # the slices the fit used (at their corrected heights)
    exposed: np.ndarray  # (K, ny, nx) bool: inside each slice's waterline
    pixel_mm: float = 0.0
    occluded: np.ndarray | None = None  # nodes under a face that hid the waterline
    rise: np.ndarray | None = None  # the meniscus correction applied per node (top - contact line)
    capillary_mm: float = 0.0  # the ink's capillary length (how far a meniscus reaches)


def _levels_and_steps(slices):
    lv = np.array([s.level for s in slices], float)
    return lv, (level_step(slices) if lv.size > 1 else 1.0)


def _frames_disagree(ev: CellEvidence, lv):
    """Per node, how far the fitted height stands above a level at which the node was
    still under the ink although an earlier frame had it out (mm; 0 where the frames
    agree, or where the fit sides with the later frames, as monotone exposure says it
    should: the earlier exposure was a transient bright thing). A node within a lattice
    spacing of the lower frame's waterline is on its edge, where the raster's side is not
    sure: that is no contradiction, nor is a node that never comes out again (the lowest
    frames can lose the part's edge from their view)."""

    K = len(ev.slices)
    lat = ev.lat
    first = np.where(ev.footprint, ev.first, K)
    last_under = np.full(lat.shape, -1)
    X, Y = np.meshgrid(lat.x, lat.y)
    tol = max(lat.hx, lat.hy)
    # out again further down: only an out-under-out pattern is a contradiction (a node
    # under in the lowest frames alone has left their view, its loop cuts a chord)
    out_below = np.zeros((K,) + lat.shape, bool)
    for k in range(K - 2, -1, -1):
        out_below[k] = out_below[k + 1] | ev.exposed[k + 1]
    for k in range(K):
        cand = ~ev.exposed[k] & (first < k) & out_below[k]
        if not cand.any() or ev.slices[k].empty:
            continue
        jj, ii = np.nonzero(cand)
        d, _ = polyline_distance(ev.slices[k], np.column_stack([X[jj, ii], Y[jj, ii]]))
        far = d > tol
        last_under[jj[far], ii[far]] = k
    above = np.zeros(lat.shape)
    bad = (last_under >= 0) & np.isfinite(ev.z)
    above[bad] = np.maximum(ev.z[bad] - lv[last_under[bad]], 0.0)
    return above


def _above_the_ink(ev: CellEvidence, lv):
    """Per node, how far the fit stands above the level of the frame before its first
    exposure (where the ink still covered it) plus the meniscus rise applied there (mm)."""
    K = len(lv)
    under = lv[np.clip(ev.first - 1, 0, K - 1)]
    lift = np.abs(np.nan_to_num(ev.rise)) if ev.rise is not None else 0.0
    above = np.where((ev.first > 0) & (ev.first < K) & np.isfinite(ev.z), ev.z - under - lift, 0.0)
    return np.maximum(above, 0.0)


def _piece_tops(ev: CellEvidence, K):
    """Per node, the first frame of the piece it came out with (the connected region of
    its first frame's exposure that holds it): where that piece's top came out."""
    first = np.where(ev.footprint, ev.first, K)
    tops = np.full(first.shape, K)
    for k in np.unique(first[first < K]):
        at = first == k
        lab, n = ndimage.label(ev.exposed[k] | at, structure=np.ones((3, 3)))
        least = np.concatenate([[K], np.asarray(ndimage.minimum(first, lab, np.arange(1, n + 1)))])
        tops[at] = least[lab[at]].astype(int)
    return tops


def _shared_meniscus(ev: CellEvidence, lv):
    """Per node, how unsure the meniscus rise is where the face does not stay open (mm):
    a share of how much more a face within a capillary length rises (the ink between them
    is one surface), and of the rise itself below the top of the node's piece, fading over
    a capillary length (the face ends above the contact line before the rise is climbed)."""
    if ev.rise is None or ev.capillary_mm <= 0:
        return np.zeros(ev.lat.shape)
    rise = np.where(ev.footprint, np.abs(np.nan_to_num(ev.rise)), 0.0)
    n = max(1, int(round(ev.capillary_mm / min(ev.lat.hx, ev.lat.hy))))
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    u_shared = ndimage.maximum_filter(rise, footprint=xx**2 + yy**2 <= n * n) - rise
    K = len(lv)
    tops = _piece_tops(ev, K)
    came_out = ev.footprint & (ev.first < K) & (tops < K)
    below_top = np.where(came_out, lv[np.minimum(tops, K - 1)] - lv[np.minimum(ev.first, K - 1)], np.inf)
    u_cut = rise * np.exp(-below_top / ev.capillary_mm)
    return RISE_SHARE * np.where(ev.footprint, np.hypot(u_shared, u_cut), 0.0)


def _nearest_distance(points, lat):
    X, Y = np.meshgrid(lat.x, lat.y)
    if len(points) == 0:
        return np.full(lat.shape, np.inf)
    # an unbalanced tree: the balanced one took 0.12 s for this query on the demo's scan
    # (its waterline points bunched along a few curves), this one 0.02; the same distances
    d, _ = cKDTree(points, balanced_tree=False).query(np.column_stack([X.ravel(), Y.ravel()]))
    return d.reshape(lat.shape)


def _inradius(region, d, floor):
    """Per node of `region`, how far in its connected piece reaches from the waterlines:
    the largest distance `d` (to the nearest seen waterline) over that piece, at least
    `floor`. A cap's middle is that far from every waterline; a ridge's crest (a long,
    thin top, a ring's) is only its half-width in, however large its area."""
    lab, n = ndimage.label(region, structure=np.ones((3, 3)))
    if n == 0:
        return np.full(region.shape, floor)
    most = ndimage.maximum(d, lab, index=np.arange(1, n + 1))
    return np.maximum(np.concatenate([[floor], np.asarray(most, float)])[lab], floor)


def _fit_residual(ev: CellEvidence, pts, zp):
    """Local RMS of the fit's misfit at the waterline points around each node."""

    lat = ev.lat
    if len(pts) == 0:
        return np.zeros(lat.shape)
    res = bilinear(lat, ev.z, pts) - zp
    ok = np.isfinite(res)
    fi, fj = lat.to_index(pts[ok])
    ii = np.clip(np.round(fi).astype(int), 0, lat.shape[1] - 1)
    jj = np.clip(np.round(fj).astype(int), 0, lat.shape[0] - 1)
    s2 = np.zeros(lat.shape)
    cnt = np.zeros(lat.shape)
    np.add.at(s2, (jj, ii), res[ok] ** 2)
    np.add.at(cnt, (jj, ii), 1.0)
    s2 = ndimage.gaussian_filter(s2, 1.5)
    cnt = ndimage.gaussian_filter(cnt, 1.5)
    return np.sqrt(s2 / np.maximum(cnt, 1e-9)) * (cnt > 1e-3)


def node_uncertainty(ev: CellEvidence, explain: dict | None = None):
    """-> (source codes, uncertainty in mm) on the lattice, NO_SOURCE / NaN off the part.
    `explain`, a dict, receives each term's field (for benches and the curious)."""

    lat = ev.lat
    h = min(lat.hx, lat.hy)
    lv, step = _levels_and_steps(ev.slices)
    K = len(ev.slices)
    top = next(k for k, s in enumerate(ev.slices) if not s.empty)
    on_curve, on_curve_z, on_wall = [], [], []
    for s in ev.slices:
        if s.empty:
            continue
        wall = s.wall if s.wall is not None else np.zeros(len(s.P), bool)
        on_curve.append(s.P[~wall])
        on_curve_z.append(s.z[~wall])
        on_wall.append(s.P[wall])
    curve_pts = np.vstack(on_curve) if on_curve else np.zeros((0, 2))
    curve_z = np.concatenate(on_curve_z) if on_curve_z else np.zeros(0)
    wall_pts = np.vstack(on_wall) if on_wall else np.zeros((0, 2))
    d_seen = _nearest_distance(curve_pts, lat)
    d_wall = _nearest_distance(wall_pts, lat)

    zf = fill_nearest(ev.z)
    gy, gx = np.gradient(zf, lat.y, lat.x)
    slope = np.hypot(gx, gy)
    gyy, gyx = np.gradient(gy, lat.y, lat.x)
    gxy, gxx = np.gradient(gx, lat.y, lat.x)
    # the larger principal curvature of the height field (its Hessian's larger |eigenvalue|)
    tr, det = gxx + gyy, gxx * gyy - 0.5 * (gxy + gyx) * 0.5 * (gxy + gyx)
    bend = np.abs(tr) / 2 + np.sqrt(np.maximum((tr / 2) ** 2 - det, 0.0))
    bend = ndimage.maximum_filter(bend, size=3)  # a kink's neighbours bend too

    # the level step around each node's first exposure (the bracket the frames give)
    fk = np.clip(ev.first, 0, K - 1)
    above = np.clip(fk - 1, 0, K - 1)
    local_step = np.where(fk > top, lv[above] - lv[fk], step)
    local_step = np.where(local_step > 0, local_step, step)

    # (how well the fit's lattice follows the waterlines is the fit term's residual, not a guess)
    lateral = LATERAL_PX * ev.pixel_mm
    u_lat = slope * lateral
    # between waterlines: the nearest seen one is d away; the bend over that distance,
    # bounded by the bracket (uniform over a step: step / sqrt(12)). Far from every
    # waterline - much further than they usually are apart on this part - nothing pins
    # the height inside its bracket: a plateau or a ridge between two levels
    d = np.where(np.isfinite(d_seen), d_seen, 0.0)
    bracket = local_step / math.sqrt(12.0)
    typical = max(float(np.median(d[ev.footprint])) if ev.footprint.any() else h, h)
    u_bend = np.minimum(0.5 * bend * d**2, bracket)
    u_far = bracket * np.clip(d / (FAR_GAPS * typical), 0.0, 1.0) ** 2
    u_gap = np.maximum(u_bend, u_far)
    # above the top frame: the top lies somewhere in the step above the highest level
    # that showed the part; the waterline pins its edge, the middle is free
    cap = (ev.first == top) & ev.footprint
    u_cap = np.where(cap, bracket * np.minimum(1.0, d / _inradius(cap, d, h)), 0.0)
    u_gap = np.maximum(u_gap, u_cap)
    # the outline: beyond it the part drops to the base; an outline placed dx off puts a
    # rim cell on the wall, up to its whole height off
    rim = ev.footprint & ~ndimage.binary_erosion(ev.footprint, np.ones((3, 3)), border_value=0)
    u_rim = np.where(rim, np.abs(zf) * np.minimum(1.0, lateral / h), 0.0)
    # the fit against the data: residuals at the waterline points near the node, and the
    # node's own first-exposure height where it has one
    pts_res = _fit_residual(ev, curve_pts, curve_z)
    # (a node's first exposure is only known within its bracket: beyond a step off, the
    # fit has overruled it - a transient exposure - and the frames' term says whether rightly)
    own = np.where(np.isfinite(ev.z_fe), np.minimum(np.abs(ev.z - ev.z_fe), local_step), 0.0)
    u_fit = np.hypot(pts_res, own)
    u_frames = _frames_disagree(ev, lv)
    # the frame before a node's first exposure had it under the ink: it stands no higher
    # than that level plus what the meniscus lifts the ink there (the correction applied);
    # a fit above that rests on nothing the frames showed (a face's rim lifted by a rise
    # meant for a wall, a spike between refined levels)
    u_bound = _above_the_ink(ev, lv)
    # the meniscus correction models a contact line on an open face; within a capillary
    # length of the outline the ink also meets the part's edge, which the model does not
    # know: the correction there is unsure by as much of it as the edge's reach leaves
    u_men = np.zeros(lat.shape)
    if ev.rise is not None and ev.capillary_mm > 0:
        # the lattice's border is the outline too (a part that fills its bounds)
        d_out = ndimage.distance_transform_edt(np.pad(ev.footprint, 1), sampling=(lat.hy, lat.hx))[1:-1, 1:-1]
        u_men = np.abs(np.nan_to_num(ev.rise)) * np.exp(-d_out / ev.capillary_mm)
    u_shared = _shared_meniscus(ev, lv)
    # the independent parts, added in quadrature; `explain` gets them by name
    parts = {
        "lateral": u_lat,
        "gap": u_gap,
        "fit": u_fit,
        "frames": u_frames,
        "bound": u_bound,
        "rim": u_rim,
        "meniscus": u_men,
        "meniscus_shared": u_shared,
    }
    u = np.sqrt(sum(p**2 for p in parts.values()))
    if explain is not None:
        explain.update(parts, gap_bend=u_bend, gap_far=u_far, gap_cap=u_cap)

    src = np.full(lat.shape, INTERPOLATED, np.int8)
    near = max(0.5 * h, 2 * ev.pixel_mm)
    src[d_seen <= near] = SEEN
    src[cap & (d_seen > near)] = EXTRAPOLATED
    src[((d_wall <= near) & (d_wall < d_seen)) | (slope > STEEP_SLOPE)] = WALL
    if ev.occluded is not None:
        src[ev.occluded] = OCCLUDED
    src[~ev.footprint] = NO_SOURCE
    u = np.where(ev.footprint, u, np.nan)
    return src, u


def to_output(lat, src, u, r, xo, yo):
    """Lattice fields on the output grid: the nearest node's source, the uncertainty
    bilinear (and never below the nearest node's: a wall node must not be averaged away)."""

    if r is not None:
        return src[::r, ::r].copy(), u[::r, ::r].copy()
    fi = (xo - lat.x[0]) / lat.hx
    fj = (yo - lat.y[0]) / lat.hy
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    ii = np.clip(np.rint(FI).astype(int), 0, lat.shape[1] - 1)
    jj = np.clip(np.rint(FJ).astype(int), 0, lat.shape[0] - 1)
    so = src[jj, ii]
    uo = ndimage.map_coordinates(fill_nearest(u), [FJ, FI], order=1, mode="nearest")
    return so, np.maximum(uo, np.where(np.isfinite(u[jj, ii]), u[jj, ii], 0.0))
