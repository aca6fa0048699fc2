"""Waterline levels: how far apart, and each loop's points on its level.

Why here: a waterline pass is a contour of the tool-tip field (waterline.py),
and the scallop between two loops is set by the height between them and the
wall's slope; where the loops stand matters as much as how many there are.

How far apart: for a corner radius rc a step dz along a wall of slope theta
leaves h = (dz / sin theta)^2 / (8 rc cos theta) vertically (verify measures
vertically), largest at the steepest wall, so dz = sin(theta) sqrt(8 rc h
cos(theta)) at the steepest slope present; a flat end's staircase leaves dz
itself. The steepest, not a high percentile: benches/steep.py's walls reach
85 degrees, their 99th percentile read 82 and left 0.066 mm for 0.05 asked.

On the level: the field is a lattice 0.2 mm apart, and marching squares draws
a contour straight between nodes; where the field bends from a floor onto a
wall within a fraction of a node its points stood on the floor or tenths of a
millimetre above their level. Each point is moved across its loop to where
the exact drop-cutter tip is the level.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .contact import drop_points
from .cutters import Cutter

MAX_WALL_DEG = 87.0  # walls steeper than this are held as if they were this steep
# the tip field's central differences on the 0.2 mm lattice read an 85-degree wall as 84.1
# (benches/steep.py): the level step is held for a wall this much steeper than read
LATTICE_READ_DEG = 1.0
FOOT = 0.04  # mm: the lowest level above the steep region's lowest tip


def level_step(cutter: Cutter, scallop: float, wall_deg: float) -> float:
    th = np.radians(min(max(wall_deg, 1.0), MAX_WALL_DEG))
    rc = cutter.corner_radius
    if rc <= 0:
        return float(scallop)
    return float(np.sin(th) * np.sqrt(8 * rc * scallop * np.cos(th)))


def steepest(field, steep) -> float:
    """The steepest slope of the tip field in `steep`, in degrees, where its 3 x 3 neighbours
    are all on the part (at the outline the slope is read against filled-in nodes). The
    steepest, not a high percentile: the scallop is largest on the steepest wall (a 99th
    percentile of 82 degrees on a part whose walls reach 85 left 0.066 mm for 0.05 asked,
    benches/steep.py), plus what the lattice's differences take off a wall's slope."""
    whole = ndimage.minimum_filter(np.isfinite(field.tip).astype(np.uint8), 3, mode="nearest") > 0
    inner = steep & whole
    return float(np.max(field.slope_deg[inner if inner.any() else steep])) + LATTICE_READ_DEG


def on_level(sampler, st, g: float, pieces, iterations: int = 8):
    """Move every point of each (piece, level) across its piece, in place, to where the
    exact drop-cutter tip is the level. The lattice's contour is straight between nodes g
    apart, and the tip field bends from the floor onto a wall within a fraction of a node:
    there its points stood on the floor or tenths of a millimetre above their level, and
    the wall between two such levels kept its scallop. Regula falsi (Illinois) on exact
    drops, bracketed within 2 g either side, alternating with bisection; a point with no
    bracket stays where it was."""
    if not pieces:
        return
    pts = np.vstack([p for p, _ in pieces])
    lv = np.concatenate([np.full(len(p), z) for p, z in pieces])
    nrm = np.vstack([_left_normals(p) for p, _ in pieces])  # uphill: higher on the left

    def f(s, k):
        if k.size == 0:
            return np.zeros(0)
        q = pts[k] + s[:, None] * nrm[k]
        return drop_points(sampler, st.cutter, q[:, 0], q[:, 1], st.resolution) - lv[k]

    every = np.arange(len(pts))
    a, fa = np.zeros(len(pts)), f(np.zeros(len(pts)), every)
    b = np.where(fa > 0, -g, g)
    fb = f(b, every)
    far = np.flatnonzero(np.sign(fa) == np.sign(fb))
    b[far] *= 2
    fb[far] = f(b[far], far)
    k = np.flatnonzero((np.sign(fa) != np.sign(fb)) & (fa != 0))
    a, fa, b, fb = a[k], fa[k], b[k], fb[k]
    side = np.zeros(k.size)  # Illinois: halve the end that stayed put twice
    for i in range(iterations):
        # bisection every other step: at a crease (a cutter on the floor touching the wall
        # with its side) the tip is flat on one side and rises ~10 mm/mm on the other, and
        # regula falsi alone crawls from the flat end
        c = 0.5 * (a + b) if i % 2 == 0 else (a * fb - b * fa) / (fb - fa)
        fc = f(c, k)
        same = np.sign(fc) == np.sign(fa)
        fb = np.where(same & (side < 0), 0.5 * fb, fb)
        fa = np.where(~same & (side > 0), 0.5 * fa, fa)
        a, fa = np.where(same, c, a), np.where(same, fc, fa)
        b, fb = np.where(same, b, c), np.where(same, fb, fc)
        side = np.where(same, -1.0, 1.0)
    s = np.zeros(len(pts))
    s[k] = np.where(np.abs(fa) < np.abs(fb), a, b)
    moved = pts + s[:, None] * nrm
    i = 0
    for p, _ in pieces:
        closed = len(p) > 2 and np.allclose(p[0], p[-1], atol=1e-6)
        p[:] = moved[i : i + len(p)]
        if closed:
            p[-1] = p[0]
        i += len(p)


def _left_normals(line):
    """Unit normals to the left of the direction of travel at each point."""
    if len(line) > 2 and np.allclose(line[0], line[-1], atol=1e-6):  # closed: wrap round
        ring = line[:-1]
        t = np.roll(ring, -1, axis=0) - np.roll(ring, 1, axis=0)
        t = np.vstack([t, t[:1]])
    else:
        t = np.gradient(line, axis=0) if len(line) > 1 else np.array([[1.0, 0.0]])
    n = np.column_stack([-t[:, 1], t[:, 0]])
    return n / np.maximum(np.hypot(*n.T), 1e-12)[:, None]
