"""Straight moves between drop-cutter tips: where to add points, where to drop them.

Refinement
----------
The drop-cutter gives exact tips at the points; between them the tool moves
in a straight line. Where the tip height is concave (the cutter rolling over
a convex edge, a link across passes) the straight move runs below the tips
it passes over and would cut in: such moves are split at their dropped
midpoints until none stands more than `refine_tolerance` below them.

Point reduction
---------------
Each run is thinned with Ramer-Douglas-Peucker to the chord tolerance:
collinear points disappear, and no dropped point is further than the
tolerance from the move that replaces it (vertically, or sideways at links).
A move above the tips it replaces adds to the scallop, one below them cuts
in: the default tolerance is 0.002 mm or a twentieth of the requested
scallop, whichever is smaller (0.0005 mm for the default 0.01 mm).
"""

from __future__ import annotations

import numpy as np

from .contact import drop_points


def refine_tolerance(chord):
    return min(chord / 4, 0.0005)


def refine(sampler, cutter, runs, tol, leave, d, max_levels=12, cand=None):
    """Split every move whose middle the cutter must pass above the straight line.

    The drop-cutter gives exact tips at the points; between them the tool
    moves in a straight line. Where the tip height is concave (the cutter
    rolling over a convex edge or corner, or a link between passes) the
    straight move runs below the tips it passes over and would cut in. Every
    move's midpoint is dropped; where it lies more than `tol` above the
    move, the midpoint is inserted and both halves are checked again. All
    runs are refined together, one drop_points call per level.
    """
    runs = [np.asarray(r, float) for r in runs]
    # candidates: (run index, segment index); start with every segment
    if cand is None:
        cand = [np.arange(max(len(r) - 1, 0)) for r in runs]
    for _ in range(max_levels):
        which = [(i, c) for i, c in enumerate(cand) if c.size]
        if not which:
            break
        mids = [0.5 * (runs[i][c] + runs[i][c + 1]) for i, c in which]
        allm = np.vstack(mids)
        long_enough = np.hypot(*(np.vstack([runs[i][c + 1] - runs[i][c] for i, c in which])[:, :2].T)) > 1e-4
        z = drop_points(sampler, cutter, allm[:, 0], allm[:, 1], d) + leave
        up_all = (z - allm[:, 2] > tol) & long_enough
        cand = [np.zeros(0, int) for _ in runs]
        pos = 0
        for (i, c), m in zip(which, mids):
            up = up_all[pos : pos + len(c)]
            zz = z[pos : pos + len(c)]
            pos += len(c)
            if not up.any():
                continue
            seg = c[up]
            new = m[up].copy()
            new[:, 2] = zz[up]
            runs[i] = np.insert(runs[i], seg + 1, new, axis=0)
            # after insertion, segment seg+k (k inserted before it) splits into two
            shift = np.arange(seg.size)
            first = seg + shift
            cand[i] = np.concatenate([first, first + 1])
    return runs


def true_runs(mask):
    m = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[0::2], edges[1::2]))


def reduce_polyline(p, tol, keep=None):
    """Ramer-Douglas-Peucker on a 3-D polyline: no dropped point is more than `tol`
    from its replacing move, vertically at the same xy nor sideways.

    Level-synchronous: every round splits *all* segments whose farthest point
    is beyond the tolerance at once, so the work is a few vectorised passes
    over the points (about log2 of their number), not one Python call per
    kept point. A segment no round splits is final, so each round looks only
    at the points of the segments the last one split. `keep` marks points
    that must stay (the ends of passes and links of a linked run), which also
    splits the work into independent pieces.
    """
    p = np.asarray(p, float)
    n = len(p)
    if n <= 2:
        return p
    keep = np.zeros(n, bool) if keep is None else np.array(keep, bool, copy=True)
    keep[0] = keep[-1] = True
    cuts = _pieces(np.flatnonzero(keep), _PIECE)
    if len(cuts) > 2:
        # no segment spans a kept point, so pieces between kept points reduce alone: a
        # rim-finished plan's linked run of 10^6 points held ~15 arrays of its size at once
        parts = [_reduce(p[a : b + 1], tol, keep[a : b + 1]) for a, b in zip(cuts[:-1], cuts[1:])]
        return np.vstack([parts[0]] + [q[1:] for q in parts[1:]])
    return _reduce(p, tol, keep)


_PIECE = 50_000  # points reduced at once, at most (unless no kept point falls between)


def _pieces(kept, size):
    """Indices of kept points that cut a run into pieces of about `size` points (first and last included)."""
    cuts = [int(kept[0])]
    for k in kept[1:].tolist():
        if k - cuts[-1] >= size:
            cuts.append(k)
    if cuts[-1] != kept[-1]:
        cuts.append(int(kept[-1]))
    return cuts


def _reduce(p, tol, keep):
    n = len(p)
    live = np.arange(n)  # the points whose segment may still be split
    while live.size:
        kept = np.flatnonzero(keep)
        seg = np.minimum(np.searchsorted(kept, live, side="right") - 1, len(kept) - 2)
        A, B, P = p[kept[seg]], p[kept[seg + 1]], p[live]
        AB = B[:, :2] - A[:, :2]
        L2 = np.einsum("ij,ij->i", AB, AB)
        AP = P[:, :2] - A[:, :2]
        t = np.einsum("ij,ij->i", AP, AB) / np.where(L2 > 0, L2, 1.0)
        t = np.clip(np.where(L2 > 0, t, 0.0), 0, 1)
        D = AP - t[:, None] * AB
        # vertical error at the same xy (what gouges), and any sideways error (corners)
        dz = np.abs(P[:, 2] - (A[:, 2] + t * (B[:, 2] - A[:, 2])))
        dist = np.maximum(np.sqrt(np.einsum("ij,ij->i", D, D)), dz)
        dist[keep[live]] = 0.0
        # live is sorted, so each segment's points are one stretch of it
        starts = np.flatnonzero(np.concatenate([[True], seg[1:] != seg[:-1]]))
        which = np.cumsum(np.concatenate([[True], seg[1:] != seg[:-1]])) - 1
        far = (dist > tol) & (dist == np.maximum.reduceat(dist, starts)[which])
        if not far.any():
            break
        cand = np.flatnonzero(far)
        _, first = np.unique(seg[cand], return_index=True)
        keep[live[cand[first]]] = True
        live = live[np.isin(seg, seg[cand[first]])]
    return p[keep]
