"""The part's edge on the output grid: the nodes just beyond its outline.

A height map says where the part is by which of its nodes have a height, and the CAM mills
a cell as part only when all four of its corners have one (cam/sampling.py): the part ends
at its last node, and beyond it the cutter may go down to the base. The true outline lies
anywhere up to a cell further out, so a finishing program cut the part's edge down to the
base over a strip up to a cell wide (1.7 mm on the dissertation's 50 x 50 grid of an 85 mm
part). Milled against the true part: a 7.6 mm gouge along the stepped block's 12 mm tier,
2.26 mm along sample 3's edge.

So a node within half a cell beyond the outline (its cell overlaps the part) takes the fit
continued out to it, no higher than the part's nearest node and no lower than the base: the
program then leaves at most half a cell of material beyond the edge where it cut up to a
whole cell into it. Such a node is on the part's outer wall, its height anything from the
base to the edge's: uniform over that.
"""

from __future__ import annotations

import math

import numpy as np

from .lattice import fill_nearest
from .slices import Slice, polyline_distance


def beyond_outline(seen: list[Slice], xo, yo, on: np.ndarray) -> np.ndarray:
    """Output nodes off the part within half a cell of its outline: the lowest frame's
    waterline, its walls put back (`seen`: the frames that show the part, top down). Only
    when that frame is within a level step of the base: a scan that stopped above it has no
    outline, its part goes on down and out (a mesa's shoulder stopped at 15 mm, its next
    nodes out held 1.6 mm too high)."""
    near = np.zeros(on.shape, bool)
    if not seen or on.all() or xo.size < 2 or yo.size < 2:
        return near
    levels = np.array([s.level for s in seen])
    step = float(np.median(-np.diff(levels))) if levels.size > 1 else 0.0
    if seen[-1].level > max(step, 0.0) + 1e-9:
        return near
    half = 0.5 * max(abs(xo[1] - xo[0]), abs(yo[1] - yo[0]))
    X, Y = np.meshgrid(xo, yo)
    off = ~on
    d, _ = polyline_distance(seen[-1], np.column_stack([X[off], Y[off]]))
    near[off] = d <= half
    return near


def with_edge_nodes(z, sigma, source, edge: np.ndarray, wall: int, fit=None):
    """z, sigma and source with the `edge` nodes on the part: `fit` there (the fit continued
    past the footprint, on the output grid; NaN where it did not reach) held between the base
    and the nearest node's height, on the wall, uncertain by that height spread over the cell
    (z / sqrt(12))."""
    if not edge.any() or not np.isfinite(z).any():
        return z, sigma, source
    level = fill_nearest(z)
    if fit is not None:
        level = np.where(np.isfinite(fit), np.clip(fit, 0.0, level), level)
    z = np.where(edge, np.maximum(level, 0.0), z)
    sigma = np.where(edge, np.hypot(fill_nearest(sigma), z / math.sqrt(12.0)), sigma)
    source = np.where(edge, wall, source).astype(source.dtype)
    return z, sigma, source
