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

    Links in the same direction are dropped together (one drop_lines call), so
    the ~200 links of a program cost about as much as one pass.
    """
    d = st.resolution
    limit = min(2.0 * (np.max(np.diff(passes)) if passes.size > 1 else st.cutter.radius), st.cutter.diameter)
    out = [None] * max(len(runs) - 1, 0)
    groups = {}
    for i in range(len(runs) - 1):
        p, q = runs[i][-1], runs[i + 1][0]
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
    todo = [i for i, l in enumerate(out) if l is not None]
    full = [np.vstack([runs[i][-1:], out[i], runs[i + 1][:1]]) for i in todo]
    # on the cores (the daemon's sphere: links rolling over its wall, 1 s alone)
    full = in_parts(
        lambda a, b: refine(sampler, cutter, full[a:b], refine_tolerance(st.chord), st.leave, d),
        [len(f) for f in full],
        joined,
    )
    for i, f in zip(todo, full):
        out[i] = f[1:-1]
    return out
