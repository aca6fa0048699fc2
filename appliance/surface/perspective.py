"""Walls as the camera sees them, and their edges put back where the walls are.

A vertical wall facing away from the camera is hidden by its own top edge, and that edge
stands higher above the ink at every lower level: its image moves away from the camera's
foot, frame after frame. A wall facing the camera shows its foot and stays put. mark_walls
finds both (waterline stretches that stay put, or move as the perspective says, between
levels); unproject_rims follows each edge up the frames to where it first showed, brackets
its height, and moves it back to where the wall is. Level-curve points lie on the ink and
stay where they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..forks import ITEM_POINTS, each_in_parts
from .slices import Slice, polyline_distance


@dataclass(frozen=True)
class Perspective:
    """Where the camera is: its foot on the base (x, y, mm) and its height above the ink.

    A point standing h above the ink at plane position x is seen at
    C + (x - C) H / (H - h): the higher, the further from the camera's foot.
    """

    xy: tuple
    height_mm: float

    @classmethod
    def of(cls, camera) -> Perspective | None:
        """A scan's camera (vision.camera.CameraModel) as the fit needs it; None when its
        calibration has no pose (no K or no height)."""
        if not camera.height_mm or camera.K is None:
            return None
        return cls(camera.centre_xy(), camera.height_mm)

    def over(self, s: Slice) -> Perspective:
        """The camera as one frame sees it: from higher up where that frame's ink fell."""
        return self if s.sight_mm is None else Perspective(self.xy, s.sight_mm)

    def true_xy(self, P, h):
        """Plane positions of points seen at P that stand h above the ink."""
        C = np.asarray(self.xy, float)
        return C + (P - C) * ((self.height_mm - np.asarray(h, float)) / self.height_mm)[..., None]


def on_fallen_ink(seen: list[Slice], true_levels, camera: Perspective) -> list[Slice]:
    """Each frame's points where they are on its fallen ink: the homography put them on the
    plane at rest, (H + d) / H too near the camera's foot (sample 1: Ea 0.17 mm, max 2.25).
    From there on the camera is H + d above that frame's ink (Slice.sight_mm): a rim or a
    contact line standing h above it is put back by h / (H + d). `seen`: the frames as
    read, at their nominal levels; `true_levels`: where their ink really was."""
    out = []
    for s, t in zip(seen, true_levels):
        # a point on ink that fell d is seen as one standing -d above the plane at rest
        fallen = s.moved(camera.true_xy(s.P, t - s.level), s.z)
        fallen.sight_mm = camera.height_mm + (s.level - t)
        out.append(fallen)
    return out


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
    top = next((s.level for s in slices if not s.empty), 0.0)
    bottom = max((k for k, s in enumerate(slices) if not s.empty), default=-1)
    # each frame against its neighbours as seen, none needing another's marks: on the cores
    marks = each_in_parts(
        lambda k: _wall_marks(slices, k, top, bottom, wall_tol_mm, camera, step_range),
        [len(s.P) + ITEM_POINTS for s in slices],
    )
    total = 0
    for s, m in zip(slices, marks):
        if m is not None:
            s.wall, s.edge = m
            s.walls_changed()
            total += int(s.wall.sum())
    return total


def _wall_marks(slices, k, top, bottom, wall_tol_mm, camera, step_range):
    """(wall, raised edge) per point of frame k (mark_walls), None for an empty frame;
    `top` the highest frame's level, `bottom` the lowest frame's index."""
    s = slices[k]
    if s.empty:
        return None
    static = np.zeros(len(s.P), bool)  # a wall facing the camera shows its foot: no move
    raised = np.zeros(len(s.P), bool)
    # The lowest frame has no frame below: the frame two up gives its raised edges a second
    # look (a rim the frame above saw a pixel off stayed a level curve, outside the rims put
    # back: five cells 0.7 mm beyond sample 4's wall). Not its static walls: two levels
    # apart, the harsh ring's crater flank passed for one (Ea 0.0354 -> 0.0461).
    for j in (k - 1, k - 2) if k == bottom else (k - 1, k + 1):
        if not (0 <= j < len(slices)) or slices[j].empty:
            continue
        if j != k - 2:
            static |= polyline_distance(slices[j], s.P)[0] < wall_tol_mm
        if camera is not None:
            dl = s.level - slices[j].level  # > 0: the neighbour is lower
            # the edge's height above the ink is unknown (0 .. top - level): take the
            # middle and widen the tolerance by what the rest of the range moves it
            h_max = max(top - s.level, 0.0) + abs(dl)
            raised |= _ray_match(
                camera.over(s),
                s.P,
                slices[j],
                dl,
                0.5 * h_max,
                step_range[1] * 0.5 * h_max,
                wall_tol_mm,
                step_range,
            )[1]
    wall = _close_gaps(s, raised | static, WALL_GAP_POINTS)
    # a raised edge moves as the perspective says (near the camera's foot it also
    # looks static: the move is then too small to matter)
    edge = wall & _close_gaps(s, raised, WALL_GAP_POINTS) if camera is not None else np.zeros(len(s.P), bool)
    return wall, edge


EDGE_HISTORY = 2  # a wall point may continue an edge seen this many level steps up
EDGE_HISTORY_MM = 2.0  # and over at least this much of level, whatever the step
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


def _edge_moved(camera: Perspective, P, dl, h, other_mm=None):
    """Where an edge seen at P, standing h above the ink, appears when the ink is dl lower
    and the camera `other_mm` above that ink (None: as high as above this one)."""
    C = np.asarray(camera.xy, float)
    H = camera.height_mm
    Hb = H if other_mm is None else other_mm
    f = np.asarray((H - h) / H * Hb / (Hb - h - dl), float)
    return C + (P - C) * (f[:, None] if f.ndim else f)


def _along_ray(camera: Perspective, P, other: Slice, dl, h, step_range):
    """Distance (and nearest vertex) from `other` to where edges seen at P appear when the
    ink is dl lower, the true step being dl times a factor in step_range."""
    lo, hi = step_range
    d, i = np.full(len(P), np.inf), np.zeros(len(P), int)
    for f in np.linspace(lo, hi, 1 if hi <= lo else 8):
        df, i_f = polyline_distance(other, _edge_moved(camera, P, f * dl, h, other.sight_mm))
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
        cam = camera.over(s)
        P = cam.true_xy(s.P, h)
        if rim_height is not None and w.size:
            # a surer edge height: the fitted surface at the edge, within the bracket
            zr = rim_height(P[w])
            ok = np.isfinite(zr)
            zr = np.clip(zr, span[w, 0], span[w, 1])
            h[w[ok]] = np.maximum(zr[ok] - s.level, 0.0)
            P = cam.true_xy(s.P, h)
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
    spans, above = [], []  # above: the frames of the last EDGE_HISTORY steps and their brackets
    short = 0.5 * _long_step(slices)
    for s in slices:
        if s.empty or s.edge is None or not s.edge.any():
            spans.append(None)
            above = _history(above + [(s, np.full((len(s.P), 2), np.nan))], short) if not s.empty else []
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
                camera.over(s),
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
        above = _history(above + [(s, span)], short)  # matched against the frames as seen
    return spans


def _long_step(slices) -> float:
    """The scan's level step as its longer steps show it (90th percentile): the ink drops
    more per step as the part comes out (harsh sample 2: 1.0 mm at the top, 1.9 at the
    base), and a refinement frame at half a step deep down is no step of its own."""
    levels = np.array([s.level for s in slices if not s.empty])
    return float(np.percentile(-np.diff(levels), 90)) if levels.size > 1 else 0.0


def _history(frames, short):
    """The frames (highest first) of the last EDGE_HISTORY level steps. A frame less than
    `short` (half a step) below the last one counted is no step of its own: the
    runner's refinement frames bisect a step 0.06-0.5 mm at a time, and counted as steps
    they left an edge's history 0.1 mm tall, too short a stretch of ray to match an edge
    a stage's play off, and its bracket started afresh below them (harsh sample 2, one
    render: the fit 0.05-0.6 mm low, Ea 0.0961 mm with its 16 such frames, 0.0197 with 4 of
    them; 0.0192 with the 16 counted by steps). Nor is it less than EDGE_HISTORY_MM of
    level: at 0.5 mm steps two steps were two frames, and two frames in a row that saw a
    wall a pixel off broke its chain (harsh sample 3: five breaks, its rims put back short,
    the levels below 0.27-0.41 mm low and Ea 0.0510 mm against 0.0162 at 1 mm steps)."""
    counted, last = 0, None
    newest = frames[-1][0].level if frames else 0.0
    reach = EDGE_HISTORY_MM - 2.0 * short  # over the newest: the next frame is a step below it
    for k in range(len(frames) - 1, -1, -1):
        level = frames[k][0].level
        if last is None or level - last >= short:
            if counted >= EDGE_HISTORY and level - newest > reach + 1e-9:
                return frames[k + 1 :]
            counted, last = counted + 1, level
    return frames


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
