"""Marching squares: where a field on a lattice crosses a level, as polylines.

The waterline passes (waterline.py) follow the contours of the tool-tip
field; the contour only says where a loop runs, the drop-cutter then says
at what height. Saddle cells are resolved by the cell centre's value, so
two loops never cross.
"""

from __future__ import annotations

import numpy as np

# corner bits: 1 (j, i), 2 (j, i+1), 4 (j+1, i+1), 8 (j+1, i); edges: 0 bottom, 1 right, 2 top, 3 left
_SEGMENTS = {
    1: [(3, 0)],
    2: [(0, 1)],
    3: [(3, 1)],
    4: [(1, 2)],
    6: [(0, 2)],
    7: [(3, 2)],
    8: [(2, 3)],
    9: [(0, 2)],
    11: [(1, 2)],
    12: [(1, 3)],
    13: [(0, 1)],
    14: [(3, 0)],
}
_SADDLE = {
    (5, True): [(0, 1), (2, 3)],
    (5, False): [(3, 0), (1, 2)],
    (10, True): [(3, 0), (1, 2)],
    (10, False): [(0, 1), (2, 3)],
}


def contours(xs, ys, F, level: float) -> list:
    """Polylines (k, 2) where the lattice field F (rows ys, columns xs) crosses `level`;
    closed ones repeat their first point."""
    v = F - level
    a, b, c, d = v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]
    valid = np.isfinite(a) & np.isfinite(b) & np.isfinite(c) & np.isfinite(d)
    case = ((a > 0) * 1 + (b > 0) * 2 + (c > 0) * 4 + (d > 0) * 8) * valid
    centre_high = (a + b + c + d) > 0
    jj, ii = np.nonzero((case > 0) & (case < 15))
    if jj.size == 0:
        return []

    def edge(j, i, e):
        """Global id and crossing point of edge e of cell (j, i)."""
        if e == 0:
            p, q, eid = (j, i), (j, i + 1), ("h", j, i)
        elif e == 2:
            p, q, eid = (j + 1, i), (j + 1, i + 1), ("h", j + 1, i)
        elif e == 3:
            p, q, eid = (j, i), (j + 1, i), ("v", j, i)
        else:
            p, q, eid = (j, i + 1), (j + 1, i + 1), ("v", j, i + 1)
        vp, vq = v[p], v[q]
        t = vp / (vp - vq)
        x = xs[p[1]] + t * (xs[q[1]] - xs[p[1]])
        y = ys[p[0]] + t * (ys[q[0]] - ys[p[0]])
        return eid, (x, y)

    point: dict[tuple, tuple] = {}
    ends: dict[tuple, list[int]] = {}
    segs: list[tuple[tuple, tuple]] = []
    for j, i in zip(jj.tolist(), ii.tolist()):
        k = int(case[j, i])
        pairs = _SADDLE[(k, bool(centre_high[j, i]))] if k in (5, 10) else _SEGMENTS[k]
        for e1, e2 in pairs:
            id1, p1 = edge(j, i, e1)
            id2, p2 = edge(j, i, e2)
            point[id1], point[id2] = p1, p2
            s = len(segs)
            segs.append((id1, id2))
            ends.setdefault(id1, []).append(s)
            ends.setdefault(id2, []).append(s)
    used = np.zeros(len(segs), bool)
    lines = []
    for s0 in range(len(segs)):
        if used[s0]:
            continue
        used[s0] = True
        chain = list(segs[s0])
        for forward in (True, False):  # grow from both ends
            while True:
                tail = chain[-1] if forward else chain[0]
                nxt = [s for s in ends[tail] if not used[s]]
                if not nxt:
                    break
                s = nxt[0]
                used[s] = True
                a_, b_ = segs[s]
                new = b_ if a_ == tail else a_
                if forward:
                    chain.append(new)
                else:
                    chain.insert(0, new)
                if chain[0] == chain[-1]:
                    break
            if chain[0] == chain[-1]:
                break
        lines.append(np.array([point[e] for e in chain], float))
    return lines
