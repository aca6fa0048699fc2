"""Silhouettes: where a face standing above the ink hides the waterline behind it.

The camera pose is known, so each waterline point's ray can be followed up through the
frames above: if it runs into the part a higher frame showed, what the camera saw there
is the rim of a face in front, not the waterline. Such points are marked as the raised
edges of walls (perspective.unproject_rims puts them back) and stay marked `hidden`, so
the cells beneath them are labelled as occluded, their heights taken from the frames that
still saw them.
"""

from __future__ import annotations

import numpy as np

from ..forks import ITEM_POINTS, each_in_parts
from .lattice import Lattice, exposed_mask
from .perspective import Perspective
from .slices import Slice, polyline_distance

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

    def seen_hidden(k):
        s = slices[k]
        hidden = np.zeros(len(s.P), bool)
        above = [j for j in range(k - 1, -1, -1) if not slices[j].empty][:frames]
        H = camera.over(s).height_mm
        for j in above:
            if not hidden.all() and not s.empty:
                Q = s.P + (C - s.P) * ((slices[j].level - s.level) / H)
                sd, _ = polyline_distance(slices[j], Q, signed=True)
                hidden |= sd >= -tol_mm
        return hidden

    # each frame against the frames above it, none needing another's: on the cores
    out = each_in_parts(seen_hidden, [len(s.P) + ITEM_POINTS for s in slices])
    # The first frames under a rim have no frame above that shows the face (it came out
    # less than a step higher): their silhouette is the one the frames below continue
    # along the same rays. Going up, a point where a hidden point's ray meets the frame
    # above is hidden too.
    for k in range(len(slices) - 1, 0, -1):
        s = slices[k]
        if s.empty or not out[k].any():
            continue
        up = next((j for j in range(k - 1, -1, -1) if not slices[j].empty), None)
        if up is None or up < k - frames:
            continue
        # (from the points no wall test found: a wall's edge lands beside the level curve
        # points next to its rim in the frame above, which would be taken along)
        src = out[k] & ~(s.edge if s.edge is not None else False)
        P = s.P[src]
        Q = P + (C - P) * ((slices[up].level - s.level) / camera.over(s).height_mm)
        d, i = polyline_distance(slices[up], Q)
        out[up][i[d <= BACK_TOL_FACTOR * tol_mm]] = True  # two outlines' noise, not one ray's
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

    def bracket(k):
        s = slices[k]
        span = np.full((len(s.P), 2), np.nan)
        h = np.flatnonzero(hidden[k]) if not s.empty else np.zeros(0, int)
        if h.size == 0:
            return span
        above = list(range(k - 1, -1, -1))
        span[h, 0] = s.level
        span[h, 1] = slices[above[0]].level if above else np.inf
        going, misses = h, np.zeros(h.size, int)
        H = camera.over(s).height_mm
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
        return span

    # each frame's rays read up the frames above it, none needing another's: on the cores
    return each_in_parts(bracket, [int(np.count_nonzero(h)) + ITEM_POINTS for h in hidden])


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
        s.walls_changed()
        total += int(hidden.sum())
    return total


def occluded_nodes(lat: Lattice, seen: list[Slice], corrected: list[Slice]) -> np.ndarray:
    """Nodes that some frame showed covered by a face standing above the ink.

    Where a frame's waterline was a silhouette (silhouettes), the camera saw
    the face's rim and the ink or part behind it was hidden; with the rims put back,
    the nodes between the rim as seen and the rim where it is are those it hid.
    Their heights come from the frames that saw them, or from the fit. `seen` are
    the slices as observed, `corrected` the same with their wall edges put back."""
    out = np.zeros(lat.shape, bool)
    for raw, cor in zip(seen, corrected):
        hidden = cor.hidden
        if raw.empty or hidden is None or not hidden.any():
            continue
        out |= exposed_mask(lat, raw) & ~exposed_mask(lat, cor)
    return out
