"""Height map -> a watertight binary STL of the part (bytes; the caller writes them).

The top is the height map's cells that have all four corners on the part, two
triangles each; the walls run down to z = 0 along every boundary edge of that
set of cells (the outline and the rims of holes); the bottom is the same cells
at z = 0. Every edge is then shared by exactly two triangles, and the normals
point out of the solid (top up, bottom down, walls away from the part).
"""

from __future__ import annotations

import struct

import numpy as np

from ..errors import InkSliceError
from .heightmap import HeightMap


def _cells(hm: HeightMap):
    ok = np.isfinite(hm.z)
    return ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:]


def heightmap_to_stl(hm: HeightMap, name: str = "inkslice") -> bytes:
    if hm.x.size < 2 or hm.y.size < 2:
        raise InkSliceError("height map", "needs at least 2 x 2 nodes to make a mesh")
    cells = _cells(hm)
    if not cells.any():
        raise InkSliceError("height map", "no cell is on the part: nothing to mesh")
    X, Y = hm.grid()
    Z = np.where(np.isfinite(hm.z), np.maximum(hm.z, 0.0), 0.0)
    j, i = np.nonzero(cells)
    p00 = np.stack([X[j, i], Y[j, i], Z[j, i]], -1)
    p10 = np.stack([X[j, i + 1], Y[j, i + 1], Z[j, i + 1]], -1)
    p01 = np.stack([X[j + 1, i], Y[j + 1, i], Z[j + 1, i]], -1)
    p11 = np.stack([X[j + 1, i + 1], Y[j + 1, i + 1], Z[j + 1, i + 1]], -1)
    tris = [np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)]  # top, CCW from above
    flat = lambda p: p * np.array([1.0, 1.0, 0.0])
    tris += [np.stack([flat(p00), flat(p11), flat(p10)], 1), np.stack([flat(p00), flat(p01), flat(p11)], 1)]
    # walls: a cell edge whose neighbour cell is not on the part
    pad = np.pad(cells, 1)
    c = pad[1:-1, 1:-1]
    sides = [  # (neighbour missing, edge start, edge end) with the part on the edge's left seen from above
        (~pad[:-2, 1:-1] & c, (0, 0), (0, 1)),  # south edge, runs +x
        (~pad[1:-1, 2:] & c, (0, 1), (1, 1)),  # east edge, runs +y
        (~pad[2:, 1:-1] & c, (1, 1), (1, 0)),  # north edge, runs -x
        (~pad[1:-1, :-2] & c, (1, 0), (0, 0)),  # west edge, runs -y
    ]
    for miss, (ja, ia), (jb, ib) in sides:
        jj, ii = np.nonzero(miss)
        a = np.stack([X[jj + ja, ii + ia], Y[jj + ja, ii + ia], Z[jj + ja, ii + ia]], -1)
        b = np.stack([X[jj + jb, ii + ib], Y[jj + jb, ii + ib], Z[jj + jb, ii + ib]], -1)
        # outward = to the right of a->b; quad a, b, b0, a0 ordered so the normal points out
        tris += [np.stack([a, flat(b), b], 1), np.stack([a, flat(a), flat(b)], 1)]
    T = np.concatenate(tris).astype(np.float64)
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(ln > 0, n / np.where(ln > 0, ln, 1), 0.0)
    rec = np.zeros(len(T), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = n
    rec["v"] = T
    header = (f"InkSlice height map {name}").encode()[:80].ljust(80, b" ")
    return header + struct.pack("<I", len(T)) + rec.tobytes()
