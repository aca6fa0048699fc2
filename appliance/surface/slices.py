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
    level: float  # free-surface level of the frame, mm
    loops: list  # list of (N, 2) arrays, as observed
    P: np.ndarray  # (M, 2) stacked points (possibly corrected positions)
    nxt: np.ndarray  # (M,) index of the next point on the same loop
    prv: np.ndarray
    z: np.ndarray  # (M,) height each point samples
    wall: np.ndarray  # (M,) bool: the point lies on a wall (mark_walls)
    edge: np.ndarray | None = None  # (M,) bool: a wall seen by its raised top edge (moves in perspective)
    hidden: np.ndarray | None = (
        None  # (M,) bool: a silhouette - a face above the ink hides the waterline there
    )
    rim: np.ndarray | None = None  # (M, 2): height bracket of the rim a silhouette point shows (NaN: none)
    # the camera's height above this frame's ink where it is not the calibrated one: the ink
    # fell under a camera fixed to the tank (perspective.on_fallen_ink); None: calibrated
    sight_mm: float | None = None
    _tree: cKDTree | None = field(default=None, repr=False)
    _curve: Slice | None = field(default=None, repr=False)

    @property
    def empty(self):
        return len(self.P) == 0

    @property
    def tree(self):
        if self._tree is None:
            self._tree = cKDTree(self.P)
        return self._tree

    def level_curve(self) -> Slice:
        """The slice without its wall points: only the stretches that are a level
        curve of the top surface (a segment with a wall end is dropped)."""
        if self._curve is None:
            wall = self.wall if self.wall is not None else np.zeros(len(self.P), bool)
            keep = np.flatnonzero(~wall)
            new = np.full(len(self.P), -1)
            new[keep] = np.arange(keep.size)
            nxt = np.where(wall[self.nxt[keep]], np.arange(keep.size), new[self.nxt[keep]])
            prv = np.where(wall[self.prv[keep]], np.arange(keep.size), new[self.prv[keep]])
            self._curve = Slice(
                self.level, [], self.P[keep], nxt, prv, self.z[keep], np.zeros(keep.size, bool)
            )
            self._curve.sight_mm = self.sight_mm
        return self._curve

    def walls_changed(self) -> None:
        """Its wall marks were changed: the level curve is derived again when next asked."""
        self._curve = None

    def moved(self, P, z):
        """The same slice with corrected point positions and heights (its loops follow
        the points: the exposed area is where the points say)."""
        loops = self.loops if P is self.P else _split_like(P, self.loops)
        return Slice(
            self.level,
            loops,
            P,
            self.nxt,
            self.prv,
            z,
            self.wall.copy(),
            None if self.edge is None else self.edge.copy(),
            None if self.hidden is None else self.hidden.copy(),
            sight_mm=self.sight_mm,
        )

    def at_level(self, level) -> Slice:
        """The same slice at another level (its point heights move with it)."""
        if abs(self.level - level) < 1e-12:
            return self
        t = self.moved(self.P, self.z + (level - self.level))
        t.level = float(level)
        return t

    def area(self):
        """Area enclosed by the waterline (holes subtract: they run clockwise)."""
        a = 0.0
        for lp in self.loops:
            x, y = lp[:, 0], lp[:, 1]
            a += 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        return a

    def length(self):
        """Length of the waterline, all its loops closed."""
        return sum(float(np.sum(np.hypot(*(np.roll(lp, -1, axis=0) - lp).T))) for lp in self.loops)


def make_slice(level, loops) -> Slice:
    loops = [np.asarray(lp, float).reshape(-1, 2) for lp in loops]
    loops = [lp for lp in loops if len(lp) >= 3 and np.all(np.isfinite(lp))]
    if not loops:
        e = np.zeros(0, int)
        return Slice(float(level), [], np.zeros((0, 2)), e, e, np.zeros(0), np.zeros(0, bool))
    P = np.vstack(loops)
    nxt_parts, prv_parts, start = [], [], 0
    for lp in loops:
        n = len(lp)
        i = np.arange(start, start + n)
        nxt_parts.append(np.roll(i, -1))
        prv_parts.append(np.roll(i, 1))
        start += n
    nxt, prv = np.concatenate(nxt_parts), np.concatenate(prv_parts)
    return Slice(float(level), loops, P, nxt, prv, np.full(len(P), float(level)), np.zeros(len(P), bool))


BASE_TOP_MM = 0.0


def shows_waterline(level_mm: float) -> bool:
    """Whether a frame at this level can hold a waterline of the part.

    At level 0 the base top reaches the ink (a real scan runs down to it) and
    below it the base stands out: the base is lit like the part, so the bright
    region's edge is the base's outline, not a level curve of the part. Read as
    one, it pinned the fit to z = 0 out at the base's edge and pulled the rim
    below the base top. Such a frame says nothing the frames above it do not."""
    return level_mm > BASE_TOP_MM + 1e-9


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
    slices: list[Slice] = []
    at_base = [items[i].level_mm for i in order if not shows_waterline(items[i].level_mm)]
    if at_base:
        order = [i for i in order if shows_waterline(items[i].level_mm)]
        notes.append(
            f"{len(at_base)} frame(s) at or below level 0 mm not used: the base top is out of "
            "the ink there, and its outline is not the part's waterline"
        )
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
        raise InkSliceError(
            "waterlines",
            f"only one level ({slices[0].level:g} mm): a height map "
            "needs at least two levels to interpolate between",
        )
    # frames below the first empty one after the part appeared cannot be: the part only grows
    # as the level drops. An empty frame BELOW visible ones means the part left the view.
    first = next(i for i, s in enumerate(slices) if not s.empty)
    for s in slices[first:]:
        if s.empty:
            raise InkSliceError(
                f"level {s.level:g} mm",
                "no part visible although higher levels "
                "showed it: the part left the view, a frame failed, or the frames "
                "contradict their levels",
            )
    _check_emerging(slices[first:])
    return slices, notes


def _check_emerging(slices):
    """Seen from above, the part only emerges as the ink drops: a frame that shows clearly
    less of it than a frame at a higher level contradicts its level (levels swapped or
    typed wrong, a frame from another scan). Ripples and noise move an outline by a
    fraction of a millimetre, far inside the tolerance."""
    most, at = 0.0, None
    for s in slices:
        area = s.area()
        if area < most - max(0.1 * most, 5.0):
            raise InkSliceError(
                f"level {s.level:g} mm",
                f"shows {area:.0f} mm² of the part, less than the "
                f"{most:.0f} mm² at {at:g} mm above it: the part only emerges as the ink drops, "
                "so the frames contradict their levels",
            )
        if area > most:
            most, at = area, s.level


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
    best = d
    if signed:
        side = np.zeros(len(q))
        n_sum = np.zeros_like(q)
    for abx, aby, aqx, aqy, L2, t, _, dd in _segments_at(sl, q, i):
        if signed:
            inner = (t > 0) & (t < 1) & (dd <= best + 1e-12)
            side = np.where(inner, np.sign(abx * aqy - aby * aqx), side)
            n_sum += np.column_stack([aby, -abx]) / np.sqrt(np.maximum(L2, 1e-300))[:, None]
        best = np.minimum(best, dd)
    if not signed:
        return best, i
    v = sl.P[i]
    at_vertex = side == 0
    side[at_vertex] = -np.sign(np.einsum("ij,ij->i", (q - v)[at_vertex], n_sum[at_vertex]))
    return np.where(side >= 0, best, -best), i


def polyline_nearest(sl: Slice, q: np.ndarray) -> np.ndarray:
    """The nearest point of the slice's polylines to each query point (on a segment, not
    only at a vertex: a straight stretch of an outline can be one long segment)."""
    best, i = sl.tree.query(q)
    out = sl.P[i].astype(float)
    for *_, foot, dd in _segments_at(sl, q, i):
        closer = dd < best
        best, out[closer] = np.minimum(best, dd), foot[closer]
    return out


def _segments_at(sl: Slice, q: np.ndarray, i: np.ndarray):
    """For the two segments at each query point's nearest vertex i (to the next vertex and
    from the previous): (ab x, ab y, aq x, aq y, |ab|^2, t, foot, distance), a the segment's
    start, foot = a + t ab the nearest point of it to q."""
    qx, qy = q[:, 0], q[:, 1]
    for a_idx, b_idx in ((i, sl.nxt[i]), (sl.prv[i], i)):
        a, b = sl.P[a_idx], sl.P[b_idx]
        ax, ay = a[:, 0], a[:, 1]
        abx, aby = b[:, 0] - ax, b[:, 1] - ay
        aqx, aqy = qx - ax, qy - ay
        L2 = abx * abx + aby * aby
        t = np.clip((aqx * abx + aqy * aby) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        fx, fy = ax + t * abx, ay + t * aby
        yield abx, aby, aqx, aqy, L2, t, np.column_stack([fx, fy]), np.hypot(qx - fx, qy - fy)


def level_step(slices: list[Slice]) -> float:
    """The scan's usual level step: the median drop from one frame to the next (0 for one)."""
    levels = np.array([s.level for s in slices], float)
    return float(np.median(-np.diff(levels))) if levels.size > 1 else 0.0


LONE_RIM_MM = 0.5  # how far one frame's rims alone may take the outline past every other's


def outline_bounds(slices: list[Slice]):
    """(xmin, xmax, ymin, ymax) of the part's outline: the lowest frame's waterline and
    every frame's wall points (one frame's alone at most LONE_RIM_MM past the others').

    The part only grows as the ink drops, so the lowest frame holds its outline - except
    where the part has left the camera's view there (sample 2's far wall is beyond the
    image in the lowest frames: that stretch of the loop is a chord across the frame's
    edge); the walls of the frames above it still show it. A higher frame's level-curve
    points add nothing but their own errors: a contact line near a rim, seen raised by
    the meniscus and not yet put back, put sample 4's outline 0.2 mm beyond its wall."""
    lowest = next(s for s in reversed(slices) if not s.empty)
    lo, hi = lowest.P.min(axis=0), lowest.P.max(axis=0)
    # each higher frame's rims, as far out as they reach; one frame alone reaches at most
    # LONE_RIM_MM past the next farthest (one frame's rims put back short - an edge's chain
    # broken there - stood 2.2 mm out and stretched the grid; a lone frame whose bracket put
    # its rim nearest the wall, 0.18 mm past the others, is right: the blade's end)
    reach = [s.P[_rim_points(s)] for s in slices if not s.empty and s.wall is not None and s is not lowest]
    reach = [r for r in reach if len(r)]
    if reach:
        lows = np.sort(np.array([r.min(axis=0) for r in reach]), axis=0)
        highs = np.sort(np.array([r.max(axis=0) for r in reach]), axis=0)
        if len(reach) >= 2:
            lows[0] = np.maximum(lows[0], lows[1] - LONE_RIM_MM)
            highs[-1] = np.minimum(highs[-1], highs[-2] + LONE_RIM_MM)
        lo, hi = np.minimum(lo, lows[0]), np.maximum(hi, highs[-1])
    return (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


def _rim_points(s: Slice):
    """The points that stand for the part's outline: walls, and with a camera only the
    edges put back from where it saw them (a wall point that was not seen moving is
    still its raised edge, 0.1-0.2 mm out near sample 4's 39 mm summit)."""
    if s.edge is not None and s.edge.any():
        return s.edge
    return s.wall


def _split_like(P, loops):
    n = np.cumsum([len(lp) for lp in loops])[:-1]
    return np.split(P, n)
