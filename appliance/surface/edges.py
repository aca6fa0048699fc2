"""The part's edge on the output grid: the nodes just beyond its outline.

A height map says where the part is by which of its nodes have a height, and the CAM mills
a cell as part only when all four of its corners have one (cam/sampling.py): the part ends
at its last node, and beyond it the cutter may go down to the base. The true outline lies
anywhere up to a cell further out, so a finishing program cut the part's edge down to the
base over a strip up to a cell wide (1.7 mm on the dissertation's 50 x 50 grid of an 85 mm
part). Milled against the true part: a 7.6 mm gouge along the stepped block's 12 mm tier,
2.26 mm along sample 3's edge.

So a node within half a cell beyond the outline (its cell overlaps the part) takes the fit
continued out to it, no higher than the part's nearest node and no lower than the base; behind
a wall the camera never saw, the middle between the base and the ray over its rim. Such a node
is on the part's outer wall, its height anything from the base to the edge's: uniform over
that. The program keeps the edge whatever the node's height (cam/sampling.py with_edges_kept):
it leaves at most half a cell of material beyond the edge where it cut up to a whole cell into it.
"""

from __future__ import annotations

import math

import numpy as np

from .lattice import fill_nearest
from .slices import Slice, level_step, polyline_distance


def beyond_outline(seen: list[Slice], xo, yo, on: np.ndarray) -> np.ndarray:
    """Output nodes off the part within half a cell of its outline: the lowest frame's
    waterline, its walls put back (`seen`: the frames that show the part, top down).

    A scan that stopped above the base has that outline only where the lowest frame ran
    along a wall, which goes on straight down (sample 3's 45 mm sides, scanned to 24 mm
    as the dissertation did); elsewhere its part goes on down and out (a mesa's shoulder
    stopped at 15 mm: its next nodes out stood 1.6 mm too high)."""
    near = np.zeros(on.shape, bool)
    if not seen or on.all() or xo.size < 2 or yo.size < 2:
        return near
    lowest = seen[-1]
    to_base = lowest.level <= max(level_step(seen), 0.0) + 1e-9
    half = 0.5 * max(abs(xo[1] - xo[0]), abs(yo[1] - yo[0]))
    X, Y = np.meshgrid(xo, yo)
    off = ~on
    d, i = polyline_distance(lowest, np.column_stack([X[off], Y[off]]))
    upright = lowest.wall | (lowest.edge if lowest.edge is not None else False)
    near[off] = (d <= half) & (to_base | upright[i])
    return near


def with_edge_nodes(z, sigma, source, edge: np.ndarray, wall: int, fit: np.ndarray, ray=None):
    """z, sigma and source with the `edge` nodes on the part: `fit` there (the fit continued
    past the footprint, on the output grid; NaN where it did not reach) held between the base
    and the nearest node's height, on the wall, uncertain by that height spread over the cell
    (z / sqrt(12)).

    `ray`: per node, the ray over a rim put back that passes over it (inf: none). Such a
    node lies behind a wall the camera never saw, nor its foot: the fit continued out to it
    only carries the top on (the stepped block's hidden 85 deg walls stood 6-7 mm over
    mid-wall). All the frames say is that it is under the ray and on the base or above: the
    middle of that. The finishing program still keeps the edge (cam/sampling.py)."""
    if not edge.any() or not np.isfinite(z).any():
        return z, sigma, source
    nearest = fill_nearest(z)
    level = np.where(np.isfinite(fit), np.clip(fit, 0.0, nearest), nearest)
    top = np.maximum(level, 0.0)
    hidden = np.zeros(z.shape, bool)
    if ray is not None:  # behind a hidden wall: no higher than the ray
        hidden = edge & np.isfinite(ray)
        top = np.where(hidden, np.clip(ray, 0.0, top), top)
    z = np.where(edge, np.where(hidden, 0.5 * top, top), z)
    sigma = np.where(edge, np.hypot(fill_nearest(sigma), top / math.sqrt(12.0)), sigma)
    source = np.where(edge, wall, source).astype(source.dtype)
    return z, sigma, source
