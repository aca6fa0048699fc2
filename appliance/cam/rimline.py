"""Pass ends off the part: their tips on a fine line, dropped once for all passes.

A pass run off the outline (margin RIM) has the cutter roll over the part's
edge, where the tip height is sharply concave: a ball's tip follows a circle
about the edge, curvature R^2 / (R^2 - r^2)^1.5, 20 /mm with the axis 2.9 mm
out for a 3 mm ball. A straight move between positions d apart cuts in
there, and refine() (polyline.py) bisected every such move up to six times,
each new point a scattered drop of the whole disc (3721 reads of the map for
a 6 mm ball at 0.1 mm): on sample 1 at scallop 0.01 that was 17 s of 62 s.

Here the moves that lie off the part and whose dropped midpoint stands above
them by more than the tolerance get FINE - 1 points each at once: one
drop_lines call per sub-position over the window of columns where any pass
has such a move, all those passes together (lines sharing a start read the
map's rows once: a point costs a row of the disc, not the disc). refine()
then sees only the fine moves that still bend by more than the tolerance.
"""

from __future__ import annotations

import numpy as np

from .contact import drop_lines

FINE = 16  # sub-positions per off-part move: chord error k (d / FINE)^2 / 8 < 1e-4 mm at k = 20 /mm


class FineEnds:
    """Fine tips of the flagged off-part moves of every pass; insert() builds a run with them."""

    def __init__(self, sampler, cutter, origins, e1, d, tips, mids, keep, off, tol, leave=0.0):
        self.tol, self.d, self.e1 = tol, d, e1
        both = keep[:, 1:] & keep[:, :-1]
        with np.errstate(invalid="ignore"):
            bent = mids - 0.5 * (tips[:, 1:] + tips[:, :-1]) > tol
        self.flag = both & bent & (off[:, 1:] | off[:, :-1])
        self.windows = []  # (first segment, passes, tips (passes, segments, FINE - 1))
        m = int(np.ceil(cutter.radius / d))
        for a, b in _windows(np.flatnonzero(self.flag.any(axis=0)), 2 * m):
            rows = np.flatnonzero(self.flag[:, a : b + 1].any(axis=1))
            z = np.stack(
                [
                    drop_lines(sampler, cutter, origins[rows] + (a + j / FINE) * d * e1, e1, b - a + 1, d)
                    for j in range(1, FINE)
                ],
                axis=2,
            )
            self.windows.append((a, rows, z + leave))

    def _fine(self, k, first, count):
        """(count, FINE - 1) fine tips of pass k's moves first..first+count-1 (nan where none)."""
        out = np.full((count, FINE - 1), np.nan)
        for a, rows, z in self.windows:
            r = np.searchsorted(rows, k)
            if r == rows.size or rows[r] != k:
                continue
            lo, hi = max(a, first), min(a + z.shape[1], first + count)
            if lo < hi:
                out[lo - first : hi - first] = z[r, lo - a : hi - a]
        return out

    def insert(self, k, pts, mid, first):
        """Pass k's run pts (positions first.. of the pass) with the fine points of its flagged
        off-part moves and the midpoints of its other bent moves inserted; returns the points and
        the moves refine() should still check."""
        if len(pts) < 2:
            return pts, np.zeros(0, int)
        nseg = len(pts) - 1
        fine = self.flag[k, first : first + nseg]
        bent = mid[:, 2] - 0.5 * (pts[:-1, 2] + pts[1:, 2]) > self.tol
        extra = np.where(fine, FINE - 1, bent.astype(int))
        if not extra.any():
            return pts, np.zeros(0, int)
        ft = self._fine(k, first, nseg)
        u = np.arange(1, FINE) / FINE
        seg = np.repeat(np.arange(nseg), extra)
        j = np.arange(seg.size) - np.repeat(np.cumsum(extra) - extra, extra)  # index within the move
        frac = np.where(fine[seg], u[np.minimum(j, FINE - 2)], 0.5)
        new = pts[seg] + frac[:, None] * (pts[seg + 1] - pts[seg])
        new[:, 2] = np.where(fine[seg], ft[seg, np.minimum(j, FINE - 2)], mid[seg, 2])
        pos = np.repeat(np.arange(1, nseg + 1), extra)
        out = np.insert(pts, pos, new, axis=0)
        start = np.concatenate([[0], np.cumsum(extra + 1)[:-1]])  # each move's first point in out
        # a split midpoint: both halves checked again; a fine move: where the line still bends
        half = np.flatnonzero(bent & ~fine)
        cand = [start[half], start[half] + 1]
        fine_pts = np.flatnonzero(np.repeat(fine, extra + 1)) if fine.any() else np.zeros(0, int)
        cand.append(_still_bent(out, fine_pts, self.tol))
        return out, np.unique(np.concatenate(cand)).astype(int)


def _still_bent(pts, idx, tol):
    """Moves from points idx (and the next) where the line of tips bends enough that the move
    between them may stand more than tol below its midpoint's tip: a quarter of the second
    difference (a parabola's chord error) over tol, on either side of a point."""
    idx = idx[(idx >= 1) & (idx <= len(pts) - 2)]
    if idx.size == 0:
        return np.zeros(0, int)
    bend = pts[idx, 2] - 0.5 * (pts[idx - 1, 2] + pts[idx + 1, 2])
    hot = idx[bend / 4 > tol]
    return np.concatenate([hot - 1, hot])


def _windows(cols, gap):
    """Contiguous stretches of sorted columns, joined across gaps up to `gap`: (first, last)."""
    if cols.size == 0:
        return []
    cut = np.flatnonzero(np.diff(cols) > gap)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [cols.size - 1]])
    return [(int(cols[s]), int(cols[e])) for s, e in zip(starts, ends)]
