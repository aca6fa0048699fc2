"""Links: the moves that keep the cutter down between neighbouring passes.

Neighbouring runs that end and start within two stepovers are joined by a
move that follows the surface (dropped like the passes, then refined where
it would cut in), so the cutter stays down between passes instead of
retracting 200 times. A link that would leave the footprint (beyond the
margin) is not made: the program builder retracts there.
"""

from __future__ import annotations

import numpy as np

from ..forks import in_parts, joined
from .contact import drop_lines
from .polyline import refine, refine_tolerance


def links(sampler, cutter, st, runs, passes):
    """Surface-following moves between consecutive runs that are neighbours, else None.

    A link needs only the ends of the two runs it joins, so the links are made in parts on
    the cores where forking is allowed (the daemon's sphere: 0.5 s in one, after the
    passes' refinement, which it waited for)."""
    limit = min(2.0 * (np.max(np.diff(passes)) if passes.size > 1 else st.cutter.radius), st.cutter.diameter)
    ends = [(runs[i][-1], runs[i + 1][0]) for i in range(len(runs) - 1)]
    return in_parts(lambda a, b: _links(sampler, cutter, st, ends[a:b], limit), np.ones(len(ends)), joined)


def _links(sampler, cutter, st, ends, limit):
    """The links of (end, start) pairs: each None where it is not made.

    Links in the same direction are dropped together (one drop_lines call), so
    the ~200 links of a program cost about as much as one pass.
    """
    d = st.resolution
    out = [None] * len(ends)
    groups = {}
    for i, (p, q) in enumerate(ends):
        gap = float(np.hypot(*(q[:2] - p[:2])))
        if gap > limit + 1e-9:
            continue
        if gap < 1e-9:
            out[i] = np.empty((0, 3))
            continue
        e = (q[:2] - p[:2]) / gap
        k = int(np.ceil(gap / d - 1e-9))  # points p + j d e, j = 1..k-1, then q
        xy = p[None, :2] + d * np.arange(1, k)[:, None] * e[None, :]
        if len(xy) and np.any(sampler.part_distance(xy[:, 0], xy[:, 1]) > st.margin + 1e-9):
            continue
        key = (round(e[0], 9), round(e[1], 9))
        groups.setdefault(key, []).append((i, p, k))
    for key, items in groups.items():
        e = np.array(key)
        n = max(k for _, _, k in items)
        if n <= 1:
            for i, _, _ in items:
                out[i] = np.empty((0, 3))
            continue
        origins = np.array([p[:2] + d * e for _, p, _ in items])
        z = drop_lines(sampler, cutter, origins, e, n - 1, d) + st.leave
        for row, (i, _p, k) in enumerate(items):
            xy = origins[row][None, :] + d * np.arange(k - 1)[:, None] * e[None, :]
            out[i] = np.column_stack([xy, z[row, : k - 1]])
    # a link runs across the passes, where the tip height may be concave: refine it
    # together with its end points, then keep only its inner points
    todo = [i for i, link in enumerate(out) if link is not None]
    full = [np.vstack([ends[i][0][None, :], out[i], ends[i][1][None, :]]) for i in todo]
    full = refine(sampler, cutter, full, refine_tolerance(st.chord), st.leave, d)
    for i, f in zip(todo, full):
        out[i] = f[1:-1]
    return out
