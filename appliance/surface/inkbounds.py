"""What the frames say for sure about each node: a floor and a ceiling.

A node inside a frame's waterline (the rims put back) was out of the ink: it stands at
least at that level. A node outside a frame's waterline as the camera saw it (a silhouette
included), and outside it with the walls put back, showed ink there: it stands below that
level. Both hold whatever the fit's smoothness would rather do, and behind a face that hid
the ink they are all the frames say: with the rims put back, a node there comes out of the
ink (in the corrected slices) only where the part around the face's foot does, at a level
the ink was never seen at - its bracket has its upper end wrong. Its ceiling is the ray
from the camera over the rim: on a face that leans like that ray (a blade's 84 deg flank),
its height.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..forks import in_parts
from .lattice import Lattice, exposed_mask
from .rimrays import SEEN_TOL_MM, under_rim_rays
from .slices import Slice, polyline_distance

FAR_NODES = 2  # lattice spacings from a frame's waterline: a node's side of it is sure


def under_flat_ink(lat: Lattice, first, slices: list[Slice], rise_max: float, lc: float):
    """Per node, the most it can stand, from the ink that covered it one frame up.

    The ink climbs a part up to rise_max at its contact line and is level again within
    a few capillary lengths: D from the contact line its surface is at most
    rise_max exp(-D / lc) above the level (the straight meniscus; a steeper one falls
    faster). A node still under the frame above's ink, FAR_NODES spacings or more from
    that frame's waterline, stands no higher. The bracket allows rise_max everywhere:
    on the blade's plate, a 6 mm strip beyond its 20 mm tip that came out at once, the
    fit carried the tip's slope 4.6 mm up into it (Ea 0.169 -> 0.129 mm with this bound).
    inf where nothing is said."""
    out = np.full(lat.shape, np.inf)
    if rise_max <= 0.0 or lc <= 0.0:
        return out
    far = FAR_NODES * max(lat.hx, lat.hy)
    X, Y = np.meshgrid(lat.x, lat.y)
    for k in np.unique(first):
        if k < 1 or k >= len(slices) or slices[k - 1].empty:
            continue
        at = first == k
        d, _ = polyline_distance(slices[k - 1], np.column_stack([X[at], Y[at]]))
        out[at] = np.where(d >= far, slices[k - 1].level + rise_max * np.exp(-d / lc), np.inf)
    return out


class NodeBounds(NamedTuple):
    hidden: np.ndarray  # nodes whose crossing of the ink a face above it hid
    floor: np.ndarray  # the highest level at which the node was out of the ink (-inf: none)
    ceiling: np.ndarray  # the lowest level at which the camera saw ink there (inf: none)
    ray: np.ndarray  # nodes whose ceiling is the ray over a rim


def node_bounds(
    lat: Lattice,
    seen: list[Slice],
    corrected: list[Slice],
    first: np.ndarray,
    footprint: np.ndarray,
    rise_max: float = 0.0,
    sink: float = 0.0,
    camera=None,
) -> NodeBounds:
    """Floor and ceiling per node of the footprint. `seen`: the slices as observed;
    `corrected`: the same with the rims put back and at their true levels; `first`: the
    frame each node came out in by the corrected slices; rise_max: the most the ink
    climbs the part (a node the ink covered stands up to that above its level, a hidden
    one not above the ray over a rim); sink: the most an ink that dewets stands above a
    face it has left (a node out of it stands up to that below its level)."""
    idx = np.flatnonzero(footprint.ravel())
    X, Y = np.meshgrid(lat.x, lat.y)
    q = np.column_stack([X.ravel()[idx], Y.ravel()[idx]])
    levels = np.array([s.level for s in corrected])

    def bounds(a, b):  # of nodes a..b: each node's sweep down the frames is its own
        first_seen, ceiling, ray = _ceiling(lat, seen, corrected, levels, q[a:b], idx[a:b])
        return first_seen, ceiling, ray, _floor(lat, corrected, levels, q[a:b], idx[a:b])

    # in halves of the nodes on the cores where forking is allowed (0.55 s of the demo
    # scan's 2.3 s fit in one)
    first_seen, ceiling, ray, floor = in_parts(bounds, np.ones(len(q)), _joined_columns)
    floor = floor - sink
    out = [np.full(lat.shape, v) for v in (False, -np.inf, np.inf, False)]
    out[1].ravel()[idx] = floor
    # the ink may climb a node a frame saw it over, but not the ray over a rim a node hid
    # behind: that is where the camera looked past the rim, whatever the ink did beyond it
    # (raised by the first ink's 3.8 mm climb, the blade's hidden flank stood 2.8 mm over its
    # truth). A ray over a node the frames did not see hidden is some frame's glitch (glare
    # on harsh sample 1's dome cut two nodes 1.2 mm): that one keeps the climb
    hidden = first_seen < first.ravel()[idx]
    out[0].ravel()[idx] = hidden
    ceiling = ceiling + np.where(ray & hidden, 0.0, rise_max)
    # and a node a face hid stands under the ray over its rim, as the frames that saw the
    # rim's silhouette pass it read that ray (the highest of their readings: rimrays.py),
    # where the frames' own levels bound it only as far as the ink might climb
    # (a rim seen within FAR_NODES of a node may pass over it; asked of hidden nodes only)
    rays = np.full(len(q), np.inf)
    rays[hidden] = under_rim_rays(q[hidden], seen, corrected, camera, FAR_NODES * max(lat.hx, lat.hy))
    under = rays < ceiling
    out[2].ravel()[idx] = np.where(under, rays, ceiling)
    out[3].ravel()[idx] = ray | under
    return _without_clashes(NodeBounds(*out))


def behind_faces(lat: Lattice, seen: list[Slice], corrected: list[Slice], first: np.ndarray) -> np.ndarray:
    """Nodes the camera saw out of the ink, in a frame before the one they came out in by
    the corrected slices, where the nearest corrected waterline is a top edge put back from
    a silhouette: what it saw there was the face over the node, not the node. The level
    they came out at is where the part beyond the face's foot crossed the ink (the blade's
    flank, 20 mm high behind its crest, came out with its 3 mm plate). A cheap cut of
    node_bounds' `hidden`, for the fit."""
    X, Y = np.meshgrid(lat.x, lat.y)
    behind = np.zeros(lat.shape, bool)
    for k, (s, c) in enumerate(zip(seen, corrected)):
        if s.empty or c.empty or c.hidden is None or not c.hidden.any():
            continue
        ask = exposed_mask(lat, s, exact_edges=True) & (first > k) & ~behind
        if ask.any():
            _, i = polyline_distance(c, np.column_stack([X[ask], Y[ask]]))
            behind[ask] = c.hidden[i]
    return behind


def _joined_columns(parts):
    return [np.concatenate(column) for column in zip(*parts)]


def _without_clashes(b: NodeBounds) -> NodeBounds:
    """A node out of the ink at a level above one at which ink was seen over it cannot be,
    on a part that is a height field: one of the two readings is a waterline's noise at a
    wall's edge (a stage that plays moves a frame's waterline by as much as SEEN_TOL_MM).
    Such a node keeps neither bound. Held to the lower one, a node on harsh sample 4's
    38.6 mm edge stood at 17.5 mm (21 mm off): the ceiling of a frame that saw ink there."""
    clash = b.floor > b.ceiling
    if not clash.any():
        return b
    return NodeBounds(
        b.hidden & ~clash,
        np.where(clash, -np.inf, b.floor),
        np.where(clash, np.inf, b.ceiling),
        b.ray & ~clash,
    )


def _ceiling(lat, seen, corrected, levels, q, idx):
    """-> (first frame showing each node inside its waterline as seen, ceiling). Where the
    ink's edge next to the node was a silhouette, the ceiling is the ray over the rim,
    between the frame that saw ink and the one below that did not."""
    K = len(seen)
    first_seen = np.full(len(q), K, np.int32)
    ceiling = np.full(len(q), np.inf)
    by_ray = np.zeros(len(q), bool)
    d_below = np.zeros(len(q))  # distance to the waterline of the frame below
    ray_below = np.zeros(len(q), bool)  # and whether a silhouette is the nearest of it
    todo = np.arange(len(q))
    below = None
    for k in range(K - 1, -1, -1):
        if seen[k].empty or todo.size == 0:
            continue
        d, near = polyline_distance(seen[k], q[todo])
        inside = _inside(lat, seen[k], q[todo], d, idx[todo])
        first_seen[todo[inside]] = k
        ink = ~inside & (d > SEEN_TOL_MM)
        ink[ink] = _outside(lat, corrected[k], q[todo[ink]], idx[todo[ink]])
        at = todo[ink]
        ceiling[at] = levels[k]
        if below is not None:
            # the node between a silhouette that passed outside it and one inside: the ray
            # over the rim crosses it in between, the silhouette creeping along that ray
            # (not when the waterline below is another one, a lower tier's outline, say)
            ray = _silhouette(corrected[k], near[ink]) & ray_below[at] & (d_below[at] > 0)
            t = d_below[at] / np.maximum(d_below[at] + d[ink], 1e-9)
            ceiling[at[ray]] = (levels[below] + t * (levels[k] - levels[below]))[ray]
            by_ray[at[ray]] = True
        d_below[todo] = d
        ray_below[todo] = _silhouette(corrected[k], near)
        todo = todo[~ink]
        below = k
    return first_seen, ceiling, by_ray


def held(z: np.ndarray, known: NodeBounds) -> np.ndarray:
    """z with every node where the frames saw it: out of the ink (over its floor), and under
    its ceiling where a face hid it or where that ceiling is the ray over a rim (the camera's
    geometry). Not every node under its ceiling: at the edge of a wall a frame's waterline
    is as far out as the stage plays, and harsh sample 4's 20 mm corner stood 3.8 mm low
    under the ink one frame saw there. Under the second ink a node on the stepped block's
    hidden wall foot, not marked hidden, stood 2.5 mm over its ray."""
    z = np.maximum(z, known.floor)
    return np.where(known.hidden | known.ray, np.minimum(z, known.ceiling), z)


def _outside(lat, s: Slice, q, flat_index) -> np.ndarray:
    """Which of the nodes the camera saw ink at lie outside the waterline with its walls put
    back too: a wall seen by its top edge looks further from the camera's foot than it is,
    and the ink beside it is where the wall's foot is, not where its edge was seen."""
    if s.empty or len(q) == 0:
        return np.ones(len(q), bool)
    d, _ = polyline_distance(s, q)
    return ~_inside(lat, s, q, d, flat_index) & (d > SEEN_TOL_MM)


def _silhouette(s: Slice, points: np.ndarray) -> np.ndarray:
    if s.hidden is None or len(s.hidden) != len(s.P):
        return np.zeros(len(points), bool)
    return s.hidden[points]


def _floor(lat, corrected, levels, q, idx):
    """The highest level whose waterline (the rims put back) has the node inside it, by
    more than a pixel."""
    floor = np.full(len(q), -np.inf)
    todo = np.arange(len(q))
    for k, s in enumerate(corrected):
        if s.empty or todo.size == 0:
            continue
        d, _ = polyline_distance(s, q[todo])
        out = _inside(lat, s, q[todo], d, idx[todo]) & (d > SEEN_TOL_MM)
        floor[todo[out]] = levels[k]
        todo = todo[~out]
    return floor


def _inside(lat: Lattice, sl: Slice, q: np.ndarray, d: np.ndarray, flat_index: np.ndarray) -> np.ndarray:
    """Which query nodes lie inside the slice's waterline, even-odd over its loops: the
    raster mask far from the waterline, an exact point-in-polygon test within two nodes of
    it (the raster takes in the nodes the waterline passes over, and on a silhouette that
    creeps 0.1 mm a level a node's width is eight levels; a glitch in a silhouette can
    turn the nearest segment's side, so not that either)."""
    inside = exposed_mask(lat, sl).ravel()[flat_index]
    near = np.flatnonzero(d < 2 * max(lat.hx, lat.hy))
    if near.size:
        count = np.zeros(near.size, int)
        for lp in sl.loops:
            count += in_polygon(lp, q[near])
        inside[near] = count % 2 == 1
    return inside


def in_polygon(loop: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Which points lie strictly inside the closed loop: cv2.pointPolygonTest(loop, point) > 0
    for every point at once, by the same crossing count in the same arithmetic (float32
    points, the crossing's sign in double), so a point on the loop is out as it is there.
    Only the edges that reach a point's row can cross it or touch it: the lattice's nodes
    share a few rows, so each row's edges are found once."""
    v = loop.astype(np.float32)
    v0 = np.roll(v, 1, axis=0)  # edge e runs from vertex e - 1 to vertex e
    p = q.astype(np.float32)
    rows, row_of = np.unique(p[:, 1], return_inverse=True)
    ry = rows[:, None]
    reach = ~(((v0[:, 1] <= ry) & (v[:, 1] <= ry)) | ((v0[:, 1] > ry) & (v[:, 1] > ry)))
    r, e = np.nonzero(reach | (v[:, 1] == ry))  # by row, then edge
    # every point meets its row's edges: the (point, edge) pairs, k indexing (r, e)
    start = np.searchsorted(r, np.arange(len(rows) + 1))  # row i's edges: e[start[i]:start[i + 1]]
    n_pairs = start[row_of + 1] - start[row_of]
    point = np.repeat(np.arange(len(p)), n_pairs)
    rank = np.arange(point.size) - np.repeat(np.cumsum(n_pairs) - n_pairs, n_pairs)
    k = start[row_of[point]] + rank
    e = e[k]
    crossing, touch = _edge_tests(p[point, 0], p[point, 1], v0[e], v[e], reach[r[k], e])
    odd = np.bincount(point, crossing, len(p)) % 2 == 1
    return odd & (np.bincount(point, touch, len(p)) == 0)


def _edge_tests(px, py, v0, v, reach):
    """Per (point, edge) pair, as pointPolygonTest's loop: does the edge cross the ray to the
    point's right, and does it touch the point (its end vertex, or along it when level)."""
    x0, y0, x, y = v0[:, 0], v0[:, 1], v[:, 0], v[:, 1]
    skip = ~reach | ((x0 < px) & (x < px))
    at_end = (py == y) & ((px == x) | ((py == y0) & (((x0 <= px) & (px <= x)) | ((x <= px) & (px <= x0)))))
    dist = (py - y0).astype(np.float64) * (x - x0) - (px - x0).astype(np.float64) * (y - y0)
    dist = np.where(y < y0, -dist, dist)
    return ~skip & (dist > 0), np.where(skip, at_end, dist == 0)
