"""Ink held in pockets: what the part carries up out of the tank.

As the base rises, the ink drains off the part wherever it can run down to the tank. A
pocket in the part's top (a bowl, a crater inside its ridge) cannot drain: once the
free surface falls below the pocket's spill height (the lowest point of its rim), the
pocket stays full to that height for the rest of the scan, and its floor is never seen.
The base lets the ink under the part (a part resting on a plate is not sealed to it), so
a hole through the part drains like the tank; only pockets in the part itself hold ink.

The spill height of every point is its priority-flood fill: the lowest height at which
the ink there could run off the part, the highest point on the best path out. The
renderer then sees, at each pixel, the free surface at max(tank level, pool surface).
"""

from __future__ import annotations

import functools
import heapq

import numpy as np
from scipy import ndimage

POCKET_STEP_MM = 0.25  # the fill's lattice: pool outlines are drawn exactly by the waterline layer
POOL_MIN_MM = 0.02  # the pool reaches the nodes this far under its spill height (past its own edge)
SPILL_MM = 0.1  # the ink runs over the lowest point of the rim until it stands this far below it


@functools.lru_cache(maxsize=4)
def pool_grid(surface):
    """-> (x0, y0, step, S): the pool surface's height S (float32, NaN where no pool) on a
    lattice over the part's bounds (one margin node round it, off the part: it drains)."""
    xmin, xmax, ymin, ymax = surface.bounds
    step = POCKET_STEP_MM
    xs = np.arange(xmin - step, xmax + 2 * step, step)
    ys = np.arange(ymin - step, ymax + 2 * step, step)
    X, Y = np.meshgrid(xs, ys)
    top = surface.height(X, Y)
    on = surface.inside(X, Y)
    fill = spill_heights(top, ~on)
    held = np.where(on & (fill > top + POOL_MIN_MM), fill - SPILL_MM, -np.inf)
    # one node wider, so that the pool's edge is where the waterline layer finds top = S,
    # not on this lattice's steps (the nodes added are above S there, dry either way)
    held = np.where(on, np.maximum(held, ndimage.grey_dilation(held, size=(3, 3))), -np.inf)
    S = np.where(np.isfinite(held), held, np.nan).astype(np.float32)
    return float(xs[0]), float(ys[0]), step, S


def spill_heights(top, drains):
    """Priority flood: for every node the lowest height at which ink there reaches a drain
    (`drains`: nodes open to the tank, and the lattice's border), over 8-neighbour paths."""
    ny, nx = top.shape
    fill = np.full(top.shape, np.inf)  # inf: not reached yet
    border = np.zeros(top.shape, bool)
    border[0, :] = border[-1, :] = border[:, 0] = border[:, -1] = True
    start = drains | border
    fill[start] = -np.inf
    heap = []
    for j, i in zip(*np.nonzero(start & ndimage.binary_dilation(~start))):
        heap.append((-np.inf, int(j), int(i)))
    heapq.heapify(heap)
    steps = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
    while heap:
        w, j, i = heapq.heappop(heap)
        for dj, di in steps:
            a, b = j + dj, i + di
            if 0 <= a < ny and 0 <= b < nx and fill[a, b] == np.inf:
                fill[a, b] = max(w, top[a, b])
                heapq.heappush(heap, (fill[a, b], a, b))
    return fill


def pool_level(surface, x, y):
    """The held pool's surface height at plane points x, y (NaN where there is none)."""
    x0, y0, step, S = pool_grid(surface)
    i = np.rint((np.asarray(x) - x0) / step).astype(np.int64)
    j = np.rint((np.asarray(y) - y0) / step).astype(np.int64)
    ok = (i >= 0) & (i < S.shape[1]) & (j >= 0) & (j < S.shape[0])
    out = np.full(np.shape(x), np.nan, np.float32)
    out[ok] = S[j[ok], i[ok]]
    return out


def held_level(surface, x0, y0, kx, ky, level, lvl):
    """The free surface each pixel's ray meets: the tank's (`lvl`, per pixel) or a pool held
    above it. -> (xs, ys, lvl): where the ray crosses that surface, and its height. A pool
    at S is seen in perspective from its own height: x0 + kx (S - level); a part has a few
    pools, each level, so each pool height is tried, the highest the ray crosses winning."""
    best = np.full(np.shape(x0), np.nan, np.float32)
    for S in pool_heights(surface):
        if S <= level:
            continue
        up = np.float32(S - level)
        there = pool_level(surface, x0 + kx * up, y0 + ky * up)
        best = np.where(np.isclose(there, S, atol=1e-4) & ~(best > S), np.float32(S), best)
    held = np.isfinite(best) & (best > lvl)
    if not held.any():
        return x0, y0, lvl
    up = np.where(held, best - level, 0.0).astype(np.float32)
    return x0 + kx * up, y0 + ky * up, np.where(held, best, lvl).astype(np.float32)


@functools.lru_cache(maxsize=4)
def pool_heights(surface) -> tuple:
    """The distinct surface heights of the part's pools."""
    S = pool_grid(surface)[3]
    return tuple(float(v) for v in np.unique(S[np.isfinite(S)]))


def under_pool(surface, x0, y0, kx, ky, level, zh, hit):
    """-> which of the rays that met the part at height zh (`hit`) met it under a held pool:
    those see the pool's ink, not the part."""
    out = np.zeros(hit.shape, bool)
    i = np.flatnonzero(hit)
    up = zh[i] - level
    S = pool_level(surface, x0[i] + kx[i] * up, y0[i] + ky[i] * up)
    out[i] = np.isfinite(S) & (zh[i] < S)
    return out
