"""Waterlines as the surface room works on them: slices with per-point heights.

A Slice is one frame's waterline after checking: its level, all its loop
points stacked (P), for each point the next and previous point of its loop
(so distances are measured to the polyline, not to its vertices), the height
each point stands for (the level, or level + meniscus rise once corrected) and
whether the point lies on a wall.

Checking the input (levels out of order, duplicated, non-finite, frames with
no part) happens here, once, with clear errors.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InkSliceError
from ..vision.types import Waterline


@dataclass
class Slice:
    level: float                 # free-surface level of the frame, mm
    loops: list                  # list of (N, 2) arrays, as observed
    P: np.ndarray                # (M, 2) stacked points (possibly corrected positions)
    nxt: np.ndarray              # (M,) index of the next point on the same loop
    prv: np.ndarray
    z: np.ndarray                # (M,) height each point samples
    wall: np.ndarray = None      # (M,) bool
    _tree: cKDTree = field(default=None, repr=False)

    @property
    def empty(self):
        return len(self.P) == 0

    @property
    def tree(self):
        if self._tree is None:
            self._tree = cKDTree(self.P)
        return self._tree

    def moved(self, P, z):
        """The same slice with corrected point positions and heights."""
        return Slice(self.level, self.loops, P, self.nxt, self.prv, z,
                     None if self.wall is None else self.wall.copy())

    def area(self):
        """Area enclosed by the waterline (holes subtract: they run clockwise)."""
        a = 0.0
        for lp in self.loops:
            x, y = lp[:, 0], lp[:, 1]
            a += 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        return a


def make_slice(level, loops) -> Slice:
    loops = [np.asarray(lp, float).reshape(-1, 2) for lp in loops]
    loops = [lp for lp in loops if len(lp) >= 3 and np.all(np.isfinite(lp))]
    if not loops:
        e = np.zeros(0, int)
        return Slice(float(level), [], np.zeros((0, 2)), e, e, np.zeros(0), np.zeros(0, bool))
    P = np.vstack(loops)
    idx, nxt, prv, start = [], [], [], 0
    for lp in loops:
        n = len(lp)
        i = np.arange(start, start + n)
        nxt.append(np.roll(i, -1))
        prv.append(np.roll(i, 1))
        start += n
    nxt, prv = np.concatenate(nxt), np.concatenate(prv)
    return Slice(float(level), loops, P, nxt, prv, np.full(len(P), float(level)), np.zeros(len(P), bool))


def check_waterlines(waterlines) -> tuple[list[Slice], list[str]]:
    """Sorted (highest level first), de-duplicated slices, and notes on what was done."""
    notes = []
    if waterlines is None or len(waterlines) == 0:
        raise InkSliceError("waterlines", "no waterlines given: a scan needs at least two levels")
    items = []
    for i, w in enumerate(waterlines):
        if not isinstance(w, Waterline):
            raise InkSliceError(f"waterline {i}", f"expected a Waterline, got {type(w).__name__}")
        if not np.isfinite(w.level_mm):
            raise InkSliceError(f"waterline {i}", f"level is not a number ({w.level_mm!r})")
        items.append(w)
    order = sorted(range(len(items)), key=lambda i: -items[i].level_mm)
    if order != list(range(len(items))):
        notes.append("levels were out of order: sorted highest first")
    slices = []
    for i in order:
        s = make_slice(items[i].level_mm, items[i].loops)
        if slices and abs(slices[-1].level - s.level) < 1e-6:
            # two frames at one level: keep the one that saw more waterline
            notes.append(f"level {s.level:g} mm given twice: kept the frame with more waterline")
            if len(s.P) > len(slices[-1].P):
                slices[-1] = s
            continue
        slices.append(s)
    seen = [s for s in slices if not s.empty]
    if not seen:
        raise InkSliceError("waterlines", "no part is visible at any level")
    if len(slices) < 2:
        raise InkSliceError("waterlines", f"only one level ({slices[0].level:g} mm): a height map "
                            "needs at least two levels to interpolate between")
    # frames below the first empty one after the part appeared cannot be: the part only grows
    # as the level drops. An empty frame BELOW visible ones means the part left the view.
    first = next(i for i, s in enumerate(slices) if not s.empty)
    for s in slices[first:]:
        if s.empty:
            raise InkSliceError(f"level {s.level:g} mm", "no part visible although higher levels "
                                "showed it (part out of view or a failed frame)")
    return slices, notes


def polyline_distance(sl: Slice, q: np.ndarray, signed: bool = False):
    """Distance from each query point to the slice's polylines, and the nearest vertex.

    With signed=True the distance is positive inside the part's exposed region
    (left of a counter-clockwise outer loop, right of a clockwise hole), decided
    by the nearest segment, or at a vertex by the sum of its two edge normals
    (the pseudo-normal): exact where a raster mask is a pixel off.
    """
    if sl.empty:
        return np.full(len(q), np.inf), np.zeros(len(q), int)
    d, i = sl.tree.query(q)
    best = d.copy()
    side = np.zeros(len(q))
    v = sl.P[i]
    n_sum = np.zeros_like(q)
    for a_idx, b_idx in ((i, sl.nxt[i]), (sl.prv[i], i)):
        a, b = sl.P[a_idx], sl.P[b_idx]
        ab = b - a
        L2 = np.einsum("ij,ij->i", ab, ab)
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        proj = a + t[:, None] * ab
        dd = np.hypot(*(q - proj).T)
        cross = ab[:, 0] * (q - a)[:, 1] - ab[:, 1] * (q - a)[:, 0]
        inner = (t > 0) & (t < 1) & (dd <= best + 1e-12)
        side = np.where(inner, np.sign(cross), side)
        best = np.minimum(best, dd)
        n_sum += np.column_stack([ab[:, 1], -ab[:, 0]]) / np.sqrt(np.maximum(L2, 1e-300))[:, None]
    if not signed:
        return best, i
    at_vertex = side == 0
    side[at_vertex] = -np.sign(np.einsum("ij,ij->i", (q - v)[at_vertex], n_sum[at_vertex]))
    return np.where(side >= 0, best, -best), i


def mark_walls(slices: list[Slice], wall_tol_mm: float) -> int:
    """Mark points whose waterline stays put to the next level down (or up): walls.

    On a sculptured top the level curve moves by step / slope between levels;
    on a wall it does not move at all. A point is a wall point when the
    neighbouring waterline passes within `wall_tol_mm` of it.
    """
    total = 0
    for k, s in enumerate(slices):
        if s.empty:
            continue
        d = np.full(len(s.P), np.inf)
        for j in (k - 1, k + 1):
            if 0 <= j < len(slices) and not slices[j].empty:
                d = np.minimum(d, polyline_distance(slices[j], s.P)[0])
        s.wall = d < wall_tol_mm
        total += int(s.wall.sum())
    return total
