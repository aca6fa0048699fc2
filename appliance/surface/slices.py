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
    wall: np.ndarray = None  # (M,) bool
    edge: np.ndarray = None  # (M,) bool: a wall seen by its raised top edge (moves in perspective)
    hidden: np.ndarray = None  # (M,) bool: a silhouette - a face above the ink hides the waterline there
    rim: np.ndarray = None  # (M, 2): height bracket of the rim a silhouette point shows (NaN: none)
    _tree: cKDTree = field(default=None, repr=False)
    _curve: Slice = field(default=None, repr=False)

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
        return self._curve

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
            None if self.wall is None else self.wall.copy(),
            None if self.edge is None else self.edge.copy(),
            None if self.hidden is None else self.hidden.copy(),
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
    slices = []
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


@dataclass(frozen=True)
class Perspective:
    """Where the camera is: its foot on the base (x, y, mm) and its height above the ink.

    A point standing h above the ink at plane position x is seen at
    C + (x - C) H / (H - h): the higher, the further from the camera's foot.
    """

    xy: tuple
    height_mm: float

    def true_xy(self, P, h):
        """Plane positions of points seen at P that stand h above the ink."""
        C = np.asarray(self.xy, float)
        return C + (P - C) * ((self.height_mm - np.asarray(h, float)) / self.height_mm)[..., None]


def mark_walls(
    slices: list[Slice], wall_tol_mm: float, camera: Perspective | None = None, step_range=(1.0, 1.0)
) -> int:
    """Mark points whose waterline stays put to the next level down (or up): walls.

    On a sculptured top the level curve moves by step / slope between levels;
    on a wall it does not move at all. A point is a wall point when the
    neighbouring waterline passes within `wall_tol_mm` of it.

    Seen from a camera over the tank, a wall facing away from it is hidden by
    its own top edge, and that edge stands higher above the ink at every lower
    level: its image moves away from the camera's foot by |x - C| dL / H per
    level step dL (0.17 mm at 50 mm from the foot, 300 mm up, 1 mm steps).
    With the camera given, the neighbour is looked for where that move puts it.
    The true step may differ from the given one by the factors in `step_range`
    (before the displacement is known: 1 to 2.5, the ink dropping further as
    the part comes out): the neighbour is looked for along that stretch of ray.
    """
    total = 0
    top = next((s.level for s in slices if not s.empty), 0.0)
    for k, s in enumerate(slices):
        if s.empty:
            continue
        static = np.zeros(len(s.P), bool)  # a wall facing the camera shows its foot: no move
        raised = np.zeros(len(s.P), bool)
        for j in (k - 1, k + 1):
            if not (0 <= j < len(slices)) or slices[j].empty:
                continue
            static |= polyline_distance(slices[j], s.P)[0] < wall_tol_mm
            if camera is not None:
                dl = s.level - slices[j].level  # > 0: the neighbour is lower
                # the edge's height above the ink is unknown (0 .. top - level): take the
                # middle and widen the tolerance by what the rest of the range moves it
                h_max = max(top - s.level, 0.0) + abs(dl)
                raised |= _ray_match(
                    camera,
                    s.P,
                    slices[j],
                    dl,
                    0.5 * h_max,
                    step_range[1] * 0.5 * h_max,
                    wall_tol_mm,
                    step_range,
                )[1]
        s.wall = _close_gaps(s, raised | static, WALL_GAP_POINTS)
        # a raised edge moves as the perspective says (near the camera's foot it also
        # looks static: the move is then too small to matter)
        s.edge = (
            s.wall & _close_gaps(s, raised, WALL_GAP_POINTS)
            if camera is not None
            else np.zeros(len(s.P), bool)
        )
        s._curve = None
        total += int(s.wall.sum())
    return total


SILHOUETTE_FRAMES = 3  # frames above a point in which its ray is looked for
SILHOUETTE_TOL_MM = 0.04  # how near the part seen at a higher level the ray may pass
SILHOUETTE_RUN = 5  # consecutive points a silhouette off the walls already found must span
BACK_TOL_FACTOR = 2.5  # up from a silhouette, its continuation: two outlines each a bit off
RIM_TOL_MM = 0.3  # two silhouettes of a crease seen edge-on, each ~a pixel off
RIM_MISSES = 2  # frames in a row the ray may miss before the rim is behind it


def silhouettes(
    slices: list[Slice],
    camera: Perspective,
    tol_mm: float = SILHOUETTE_TOL_MM,
    frames: int = SILHOUETTE_FRAMES,
) -> list[np.ndarray]:
    """Per slice: which of its points are silhouettes, not waterlines.

    The camera sees a plane point P of the ink at level L along the ray from its
    centre; at height h above the ink that ray is at P + (C - P) h / H. A frame
    at a higher level L' showed where the part stands at least L' high. If the
    ray, at height L' - L, is inside that region (or grazes it, within tol_mm),
    a face above the ink stands in front of P: what the camera saw there is the
    rim of that face, not the waterline. A waterline on a face the camera sees
    passes that test by a margin that grows with the height: its ray leaves the
    part behind as it rises. Pure: the slices are as observed, before any wall
    edge is put back."""
    C = np.asarray(camera.xy, float)
    H = camera.height_mm
    out = []
    for k, s in enumerate(slices):
        hidden = np.zeros(len(s.P), bool)
        above = [j for j in range(k - 1, -1, -1) if not slices[j].empty][:frames]
        for j in above:
            if not hidden.all() and not s.empty:
                Q = s.P + (C - s.P) * ((slices[j].level - s.level) / H)
                sd, _ = polyline_distance(slices[j], Q, signed=True)
                hidden |= sd >= -tol_mm
        out.append(hidden)
    # The first frames under a rim have no frame above that shows the face (it came out
    # less than a step higher): their silhouette is the one the frames below continue
    # along the same rays. Going up, a point where a hidden point's ray meets the frame
    # above is hidden too.
    for k in range(len(slices) - 1, 0, -1):
        s = slices[k]
        if s.empty or not out[k].any():
            continue
        j = next((j for j in range(k - 1, -1, -1) if not slices[j].empty), None)
        if j is None or j < k - frames:
            continue
        # (from the points no wall test found: a wall's edge lands beside the level curve
        # points next to its rim in the frame above, which would be taken along)
        src = out[k] & ~(s.edge if s.edge is not None else False)
        P = s.P[src]
        Q = P + (C - P) * ((slices[j].level - s.level) / H)
        d, i = polyline_distance(slices[j], Q)
        out[j][i[d <= BACK_TOL_FACTOR * tol_mm]] = True  # two outlines' noise, not one ray's
    return out


def rim_brackets(
    slices: list[Slice], camera: Perspective, hidden: list[np.ndarray], tol_mm: float = RIM_TOL_MM
) -> list[np.ndarray]:
    """Per slice, (M, 2): the height bracket (lo, hi) of the rim each silhouette point
    shows (NaN for the other points).

    Up its ray, frame after frame, the rim's silhouette continues for as long as the
    face stands above that frame's ink: the highest frame whose region the ray still
    grazes is at or below the rim, the next one up above it. Read along the ray from
    the observations alone, the bracket does not depend on matching each point to its
    neighbour frame by frame (a chain that one noisy frame breaks); a frame or two
    where the ray misses by more than tol_mm (a silhouette a pixel off) do not end it."""
    C = np.asarray(camera.xy, float)
    H = camera.height_mm
    out = []
    for k, s in enumerate(slices):
        span = np.full((len(s.P), 2), np.nan)
        h = np.flatnonzero(hidden[k]) if not s.empty else np.zeros(0, int)
        if h.size == 0:
            out.append(span)
            continue
        above = [j for j in range(k - 1, -1, -1)]
        span[h, 0] = s.level
        span[h, 1] = slices[above[0]].level if above else np.inf
        going, misses = h, np.zeros(h.size, int)
        for n, j in enumerate(above):
            if going.size == 0 or slices[j].empty:
                break
            Q = s.P[going] + (C - s.P[going]) * ((slices[j].level - s.level) / H)
            sd, _ = polyline_distance(slices[j], Q, signed=True)
            on = sd >= -tol_mm
            span[going[on], 0] = slices[j].level
            span[going[on], 1] = slices[above[n + 1]].level if n + 1 < len(above) else np.inf
            misses = np.where(on, 0, misses + 1)
            keep = misses < RIM_MISSES
            going, misses = going[keep], misses[keep]
        out.append(span)
    return out


def _in_runs(s: Slice, flag, n):
    """Points of `flag` in a run of at least n consecutive flagged points along their loop."""
    back = np.zeros(len(flag), int)
    fwd = np.zeros(len(flag), int)
    a, b = np.arange(len(flag)), np.arange(len(flag))
    alive_a, alive_b = flag.copy(), flag.copy()
    for _ in range(n - 1):
        a, b = s.prv[a], s.nxt[b]
        alive_a &= flag[a]
        alive_b &= flag[b]
        back += alive_a
        fwd += alive_b
    return flag & (back + fwd + 1 >= n)


def mark_silhouettes(slices: list[Slice], camera: Perspective, tol_mm: float = SILHOUETTE_TOL_MM) -> int:
    """Mark each slice's silhouette points (`silhouettes`) as the raised edges of walls.

    What the camera sees there is the rim of a face standing above the ink, exactly
    what it sees of a vertical wall facing away from it: a wall edge, to be put back
    where the rim is (unproject_rims), never a level curve of the top. The points stay
    marked `hidden` for whoever labels the cells beneath them."""
    total = 0
    hidden_all = silhouettes(slices, camera, tol_mm)
    for s, hidden, rim in zip(slices, hidden_all, rim_brackets(slices, camera, hidden_all)):
        if s.empty:
            s.hidden, s.rim = hidden, rim
            continue
        if s.wall is not None and s.edge is not None:
            # a wall that stays put is seen by its foot (it faces the camera); near the
            # camera's foot its ray rises almost along it and grazes it
            hidden = hidden & ~(s.wall & ~s.edge)
            # a silhouette is a stretch of rim: a point or two of a level curve whose ray
            # grazes the frame above within the noise is not one
            hidden &= s.wall | _in_runs(s, hidden, SILHOUETTE_RUN)
            rim[~hidden | s.edge] = np.nan  # edges found frame to frame keep their chain
        s.hidden = hidden
        s.rim = rim
        s.wall = hidden if s.wall is None else s.wall | hidden
        s.edge = hidden if s.edge is None else s.edge | hidden
        s._curve = None
        total += int(hidden.sum())
    return total


EDGE_HISTORY = 2  # a wall point may continue an edge seen this many frames up
WALL_GAP_POINTS = 4  # a run of up to this many non-wall points between wall points is wall


def _close_gaps(s: Slice, wall, n):
    """A few points along a wall that missed the test (noise) are wall all the same:
    left as a level curve they would claim the ink's level a wall's height away."""
    left = np.zeros_like(wall)
    right = np.zeros_like(wall)
    a, b = np.arange(len(wall)), np.arange(len(wall))
    for _ in range(n):
        a, b = s.prv[a], s.nxt[b]
        left |= wall[a]
        right |= wall[b]
    return wall | (left & right)


def _edge_moved(camera: Perspective, P, dl, h):
    """Where an edge seen at P, standing h above the ink, appears when the ink is dl lower."""
    C = np.asarray(camera.xy, float)
    H = camera.height_mm
    f = np.asarray((H - h) / (H - h - dl), float)
    return C + (P - C) * (f[:, None] if f.ndim else f)


def _along_ray(camera: Perspective, P, other: Slice, dl, h, step_range):
    """Distance (and nearest vertex) from `other` to where edges seen at P appear when the
    ink is dl lower, the true step being dl times a factor in step_range."""
    lo, hi = step_range
    d, i = np.full(len(P), np.inf), np.zeros(len(P), int)
    for f in np.linspace(lo, hi, 1 if hi <= lo else 8):
        df, i_f = polyline_distance(other, _edge_moved(camera, P, f * dl, h))
        better = df < d
        d, i = np.where(better, df, d), np.where(better, i_f, i)
    return d, i


def unproject_rims(
    slices: list[Slice],
    camera: Perspective,
    wall_tol_mm: float,
    rim_height=None,
    rise_max: float = 0.0,
    step_range=(1.0, 1.0),
) -> list[Slice]:
    """Move each wall point from where the camera sees its top edge to where the wall is.

    A wall's top edge at height z0 first shows at the highest level below z0,
    hardly raised; at every lower level it stands z0 - L above the ink and is
    seen further out. Going down the levels, a wall point inherits the edge
    height of the wall point it continues (found where the perspective puts it
    in the frame above or two above; of two, the edge that showed first); a wall
    point with none above is a new edge: z0 lies between this level and the one
    above (plus the meniscus' rise, if any) - unless its neighbours along the wall
    continue an edge, when it is a glitch of this frame and takes theirs. Every
    point with a bracket comes back marked as an edge.
    Level-curve points lie on the ink and stay where they are.
    """
    spans = _edge_brackets(slices, camera, wall_tol_mm, rise_max, step_range)
    out = []
    for s, span in zip(slices, spans):
        if span is None:
            out.append(s)
            continue
        if s.rim is not None:
            # a silhouette's rim is bracketed along its own ray (rim_brackets) where that
            # finds it higher up than the frame-to-frame chain did (a chain broken by a frame
            # a pixel off starts afresh, low): the edge that showed first wins
            own = np.isfinite(s.rim[:, 0]) & ~(span[:, 0] >= s.rim[:, 0])
            span = span.copy()
            span[own] = s.rim[own] + np.array([0.0, rise_max])
            span[own, 1] = np.where(np.isfinite(span[own, 1]), span[own, 1], span[own, 0] + 1.0 + rise_max)
        edge = np.isfinite(span[:, 0])
        w = np.flatnonzero(edge)
        z0 = span.mean(axis=1)
        h = np.where(np.isfinite(z0), np.maximum(z0 - s.level, 0.0), 0.0)
        P = camera.true_xy(s.P, h)
        if rim_height is not None and w.size:
            # a surer edge height: the fitted surface at the edge, within the bracket
            zr = rim_height(P[w])
            ok = np.isfinite(zr)
            zr = np.clip(zr, span[w, 0], span[w, 1])
            h[w[ok]] = np.maximum(zr[ok] - s.level, 0.0)
            P = camera.true_xy(s.P, h)
        t = s.moved(P, s.z)
        t.edge = edge
        out.append(t)
    return out


def _ray_match(camera, P, frame: Slice, dl, h, h_spread, wall_tol_mm, step_range):
    """(nearest vertex, within tolerance) in `frame` of the edges seen at P, standing h
    above the ink, where the ink is dl lower there (< 0: a frame above). The tolerance
    grows by what an edge h_spread higher or lower would move differently."""
    d, i = _along_ray(camera, P, frame, dl, h, step_range)
    r = np.hypot(*(P - np.asarray(camera.xy, float)).T)
    return i, d < wall_tol_mm + r * abs(dl) * h_spread / camera.height_mm**2


def _edge_brackets(slices, camera, wall_tol_mm, rise_max, step_range):
    """Per frame: each wall point's edge height as a bracket (lo, hi) - where it first
    showed - (None for a frame without wall points)."""
    spans, above = [], []  # above: the last EDGE_HISTORY frames and their brackets
    for s in slices:
        if s.empty or s.edge is None or not s.edge.any():
            spans.append(None)
            above = (above + [(s, np.full((len(s.P), 2), np.nan))])[-EDGE_HISTORY:] if not s.empty else []
            continue
        step_up = (above[-1][0].level - s.level) if above else 1.0
        span = np.full((len(s.P), 2), np.nan)
        w = np.flatnonzero(s.edge)
        # (a meniscus keeps the edge under until the ink is its rise below it: up to rise_max)
        span[w] = (s.level, s.level + step_up + rise_max)
        for frame, span_above in above:
            # where the edge was a level up, or two (one frame's edge can be a pixel off, and
            # the chain would start afresh below it; the true step may be the given one times
            # step_range: the match looks along that stretch of ray). Of two matches the
            # edge that showed first wins: a point continuing a frame's glitch (itself a
            # "new" edge) would otherwise carry the glitch's bracket all the way down
            dl = s.level - frame.level
            i, near = _ray_match(
                camera,
                s.P[w],
                frame,
                dl,
                0.5 * abs(dl),
                0.5 * max(slices[0].level - s.level, 1.0),
                wall_tol_mm,
                step_range,
            )
            cand = span_above[i]
            older = near & (cand[:, 0] > span[w, 0])  # NaN (no edge there) compares False
            span[w[older]] = cand[older]
        span = _mend_along_wall(s, span)
        spans.append(span)
        above = (above + [(s, span)])[-EDGE_HISTORY:]  # matched against the frames as seen
    return spans


def _mend_along_wall(s: Slice, span, n=WALL_GAP_POINTS):
    """A point of a wall whose edge is known on both sides along the loop (within n points,
    through wall points only) but that itself starts afresh, or was not seen raised at all,
    is a glitch of this frame (a rim point a pixel off): it takes its neighbours' bracket.
    Repeated while it mends more: a glitch a few points longer than n mends from its ends."""
    while True:
        known = np.isfinite(span[:, 0]) & (span[:, 0] > s.level)  # continues an edge from above
        suspect = s.wall & ~known
        if not suspect.any() or not known.any():
            return span
        sides = [_nearest_along(s, suspect, known, step, span, n) for step in (s.prv, s.nxt)]
        fix = suspect & np.isfinite(sides[0][:, 0]) & np.isfinite(sides[1][:, 0])
        if not fix.any():
            return span
        span = span.copy()
        span[fix, 0] = np.minimum(sides[0][fix, 0], sides[1][fix, 0])
        span[fix, 1] = np.maximum(sides[0][fix, 1], sides[1][fix, 1])


def _nearest_along(s, start, known, step, span, n):
    """For the `start` points: the span of the first `known` point within n steps along the
    loop (prv or nxt), walking over wall points only (NaN where there is none)."""
    found = np.full((len(s.P), 2), np.nan)
    open_ = start.copy()
    j = np.arange(len(s.P))
    for _ in range(n):
        j = step[j]
        hit = open_ & known[j]
        found[hit] = span[j[hit]]
        open_ &= ~hit & s.wall[j]
    return found


def outline_bounds(slices: list[Slice]):
    """(xmin, xmax, ymin, ymax) of the part's outline: the lowest frame's waterline and
    every frame's wall points.

    The part only grows as the ink drops, so the lowest frame holds its outline - except
    where the part has left the camera's view there (sample 2's far wall is beyond the
    image in the lowest frames: that stretch of the loop is a chord across the frame's
    edge); the walls of the frames above it still show it. A higher frame's level-curve
    points add nothing but their own errors: a contact line near a rim, seen raised by
    the meniscus and not yet put back, put sample 4's outline 0.2 mm beyond its wall."""
    lowest = next(s for s in reversed(slices) if not s.empty)
    P = np.vstack([lowest.P] + [s.P[_rim_points(s)] for s in slices if not s.empty and s.wall is not None])
    return (float(P[:, 0].min()), float(P[:, 0].max()), float(P[:, 1].min()), float(P[:, 1].max()))


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
