"""Pass ends off the part: their tips on a fine line, dropped once for all passes.

A pass run off the outline (margin RIM) has the cutter roll over the part's
edge, where the tip height is sharply concave: a ball's tip follows a circle
about the edge, curvature R^2 / (R^2 - r^2)^1.5, 20 /mm with the axis 2.9 mm
out for a 3 mm ball. A straight move between positions d apart cuts in
there, and refine() (polyline.py) bisected every such move up to twelve
times, each new point a scattered drop of the whole disc (3721 reads of the
map for a 6 mm ball at 0.1 mm): on sample 1 at scallop 0.01 that was 40 % of
the program's time.

Here the moves that lie off the part and whose dropped midpoint stands above
them by more than the tolerance get up to MAX_SUB - 1 tips each at once: one
drop_fine_lines call over the window of columns where any pass has such a
move, all those passes together, every sub-position read on the lines' own
lattice (one slab for all of them; a lattice centred on each sub-position
read a slab per sub-position, mostly its margins: 5-7x the time). Every other sub-position is a fine point, and the
ones between are the fine moves' midpoints, checked as refine() checks: a
midpoint above its fine move by more than the tolerance is inserted and
both halves go on to refine(). Nothing is estimated: every move that stays
was checked at its middle (a withdrawn first version guessed the bent fine
moves from second differences, and sample 4's bull nose gouged 0.0004 mm
more).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..forks import in_parts, joined
from .fineline import drop_fine_lines

MAX_SUB = 32  # sub-positions per off-part move: 15 fine points and 16 midpoints checking them


def _subdivisions(sag, tol):
    """Sub-positions per move for moves standing up to `sag` below their midpoints: a
    parabola's chord error falls as the square of the move's length, so sqrt(sag / tol)
    fine moves (a power of two, at least two), twice as many sub-positions."""
    k = 2.0 ** np.ceil(np.log2(np.maximum(np.sqrt(np.maximum(sag, 0.0) / tol), 2.0)))
    return np.minimum(2 * k, MAX_SUB).astype(int)


class FineEnds:
    """Fine tips of the flagged off-part moves of every pass; insert() builds a run with them."""

    def __init__(self, sampler, cutter, origins, e1, d, tips, mids, keep, off, tol, leave=0.0):
        self.tol = tol
        both = keep[:, 1:] & keep[:, :-1]
        rise = mids - 0.5 * (tips[:, 1:] + tips[:, :-1])  # each move's dropped middle above it
        with np.errstate(invalid="ignore"):
            self.flag = both & (rise > tol) & (off[:, 1:] | off[:, :-1])
        sag = np.where(self.flag, rise, 0.0)
        m = int(np.ceil(cutter.radius / d))
        boxes = _tiles(self.flag, 2 * m)
        # (first move, passes, slots per fine move (passes, moves), tips on slots) per box; the
        # boxes on the cores, in parts of about equal area (the daemon's sphere: 1.7 s alone)
        self.windows = in_parts(
            lambda i, j: [
                _window(sampler, cutter, origins, e1, d, self.flag, sag, tol, leave, *box)
                for box in boxes[i:j]
            ],
            [rows.size * (b - a + 1) for a, b, rows in boxes],
            joined,
        )

    def _fine(self, k, first, count):
        """Sub-position tips of pass k's moves first..first+count-1 on MAX_SUB - 1 slots (a move
        of `sub` sub-positions fills every MAX_SUB / sub-th; nan elsewhere), and that spacing
        in slots per move (0 where the move has none)."""
        out = np.full((count, MAX_SUB - 1), np.nan)
        step = np.zeros(count, int)
        for a, rows, q, slots in self.windows:
            r = np.searchsorted(rows, k)
            if r == rows.size or rows[r] != k:
                continue
            lo, hi = max(a, first), min(a + slots.shape[1], first + count)
            if lo < hi:
                out[lo - first : hi - first] = slots[r, lo - a : hi - a]
                step[lo - first : hi - first] = q[r, lo - a : hi - a]
        return out, step

    def insert(self, k, pts, mid, first):
        """Pass k's run pts (positions first.. of the pass) with its checked points inserted:
        the fine points of its flagged off-part moves and the fine moves' midpoints that stand
        above them, and the midpoints of its other bent moves. Returns the points and the moves
        refine() should check further (both halves of every inserted midpoint)."""
        if len(pts) < 2:
            return pts, np.zeros(0, int)
        nseg = len(pts) - 1
        fine = self.flag[k, first : first + nseg].copy()
        bent = mid[:, 2] - 0.5 * (pts[:-1, 2] + pts[1:, 2]) > self.tol
        if not (fine.any() or bent.any()):
            return pts, np.zeros(0, int)
        # per move and slot (fraction (slot + 1) / MAX_SUB): the points it gets, their
        # heights, and which of them are checked midpoints
        take = np.zeros((nseg, MAX_SUB - 1), bool)
        checked = np.zeros((nseg, MAX_SUB - 1), bool)
        z = np.full((nseg, MAX_SUB - 1), np.nan)
        if fine.any():
            ft, step = self._fine(k, first, nseg)
            f = np.flatnonzero(fine & (step > 0))
            chain = np.column_stack([pts[f, 2], ft[f], pts[f + 1, 2]])  # slots 0..MAX_SUB
            for q in np.unique(step[f]):
                g = np.flatnonzero(step[f] == q)
                odd = q * np.arange(1, MAX_SUB // q, 2)
                c = chain[g]
                up = c[:, odd] - 0.5 * (c[:, odd - q] + c[:, odd + q]) > self.tol
                take[f[g, None], odd[None, 1:] - q - 1] = True  # the fine points between them
                take[f[g, None], odd[None, :] - 1] = up
                checked[f[g, None], odd[None, :] - 1] = up
            z[f] = ft[f]
            fine[:] = False
            fine[f] = True
        plain = np.flatnonzero(bent & ~fine)
        half = MAX_SUB // 2 - 1
        take[plain, half], checked[plain, half], z[plain, half] = True, True, mid[plain, 2]
        seg, j = np.nonzero(take)  # row-major: in order along the run
        new = pts[seg] + ((j + 1) / MAX_SUB)[:, None] * (pts[seg + 1] - pts[seg])
        new[:, 2] = z[seg, j]
        # a plain move's midpoint is the one dropped (the same digits as before the fine lines)
        own = np.isin(seg, plain)
        new[own] = mid[seg[own]]
        out = np.insert(pts, seg + 1, new, axis=0)
        q = (seg + 1 + np.arange(seg.size))[checked[seg, j]]  # inserted midpoints' indices in out
        return out, np.unique(np.concatenate([q - 1, q])).astype(int)


def _window(sampler, cutter, origins, e1, d, flag_all, sag, tol, leave, a, b, rows):
    """One box's fine tips: (first move, passes, slots per fine move, tips on slots)."""
    flag = flag_all[rows, a : b + 1]
    # a move's count from the largest sag of it and its neighbours, for a quarter of
    # the tolerance: thinning (reduce_polyline) checks the chord only at these
    # points, and from the move's own sag at the tolerance a point between two of
    # them stood 0.0022 mm above the thinned move where 0.002 was asked (the window's
    # largest sag for every move, as before: 0.0020)
    near = ndimage.maximum_filter1d(sag[rows], 3, axis=1)[:, a : b + 1]
    each = np.where(flag, _subdivisions(4 * near, tol), 0)
    sub = int(each.max())
    # every sub-position of the window's moves read at once on the lines' own lattice;
    # polished (the exact contacts: most of the cost on a coarse map) only where a
    # move's own count needs it (one sag in a window asked 32 of every move: the
    # daemon's sphere, its whole wall at the outline's foot, 6 s of polish)
    j = np.arange(sub)
    stride = sub // np.maximum(each, 1)  # a move's own sub-positions among the window's
    need = flag[:, :, None] & (j > 0) & (j % stride[:, :, None] == 0)
    z = drop_fine_lines(
        sampler,
        cutter,
        origins[rows] + a * d * e1,
        e1,
        (b - a + 1) * sub,
        d,
        sub,
        need=need.reshape(rows.size, -1),
    )
    slots = np.full((rows.size, b - a + 1, MAX_SUB - 1), np.nan)
    slots[:, :, (MAX_SUB // sub) * j[1:] - 1] = z.reshape(rows.size, b - a + 1, sub)[:, :, 1:] + leave
    return a, rows, np.where(flag, MAX_SUB // np.maximum(each, 1), 0), slots


def _tiles(flag, gap):
    """(first move, last move, passes) boxes covering every flagged move, the passes taken
    together where they share columns.

    The passes that roll over a straight outline square to them are flagged in the same
    few columns, and one box over all of them reads one slab. A round outline crosses
    every column somewhere: one box of the columns flagged by any pass, times every pass,
    was the whole map (the daemon's sphere: 20 s and 540 MB more). So consecutive passes
    are grouped while the group's windows (its flagged columns joined across gaps up to
    `gap`) times its passes stay within twice what each pass's own windows hold.
    """
    groups, group, cols, own = [], [], np.zeros(flag.shape[1], bool), 0
    for k in np.flatnonzero(flag.any(axis=1)):
        width = _width(flag[k], gap)
        union = cols | flag[k]
        if group and (len(group) + 1) * _width(union, gap) > 2 * (own + width):
            groups.append(group)
            group, union, own = [], flag[k].copy(), 0
        group.append(k)
        cols, own = union, own + width
    if group:
        groups.append(group)
    boxes = []
    for rows in map(np.array, groups):
        sub = flag[rows]
        for a, b in _windows(np.flatnonzero(sub.any(axis=0)), gap):
            boxes.append((a, b, rows[sub[:, a : b + 1].any(axis=1)]))
    return boxes


def _width(cols, gap):
    """Columns the windows of a row of flags span."""
    return sum(b - a + 1 for a, b in _windows(np.flatnonzero(cols), gap))


def _windows(cols, gap):
    """Contiguous stretches of sorted columns, joined across gaps up to `gap`: (first, last)."""
    if cols.size == 0:
        return []
    cut = np.flatnonzero(np.diff(cols) > gap)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [cols.size - 1]])
    return [(int(cols[s]), int(cols[e])) for s, e in zip(starts, ends)]
