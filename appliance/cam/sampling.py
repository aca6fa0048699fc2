"""Reading a height map between its samples, and where the part is.

Every CAM step reads the height map at points that are not lattice nodes
(toolpath points, the dilation's offsets, simulation cells). We use ONE
interpolation everywhere so that the drop-cutter, the planner and the
verification agree on what "the design surface" is: piecewise linear on two
triangles per cell, split along the diagonal from (i, j) to (i+1, j+1).
That is exactly the triangle mesh we hand OpenCAMLib in the benchmark and the
surface an STL export of the same map describes, so "agrees with OpenCAMLib"
is a statement about the same surface, not about two interpolations.

Off the part (a NaN corner, or outside the lattice) the surface is the floor:
the base top, z = 0, on which the part stands. A cutter may go down there but
never below it.

The part's outer edge is a cliff, and a drop-cutter that only sees the
surface on its offset lattice misses the edge itself whenever the lattice
straddles it, and dips past it (we measured 0.05 mm gouges along the edge of
sample 3 that way). So the sampler also offers the footprint's boundary as a
set of straight 3-D segments (`edges`: the lattice sides on the boundary,
heights from the part's side, plus every side inside the part steeper than
45 degrees, i.e. walls), which the drop-cutter tests exactly as contacts in
their own right (segments.py). Steep *facets* are still only seen on the
lattice: on very steep surfaces use a finer resolution (sample 4 gets 0.02 mm).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..errors import InkSliceError
from ..surface.base import interior_holes
from ..surface.heightmap import HeightMap

FLOOR = 0.0


def check_heightmap(hm: HeightMap, where="height map"):
    """Refuse maps the CAM cannot mill sensibly, naming the problem."""
    if hm.x.size < 2 or hm.y.size < 2:
        raise InkSliceError(where, f"needs at least 2 x 2 samples, has {hm.x.size} x {hm.y.size}")
    for name, v in (("x", hm.x), ("y", hm.y)):
        d = np.diff(v)
        if np.any(d <= 0) or np.ptp(d) > 1e-6 * max(1.0, float(np.max(np.abs(v)))):
            raise InkSliceError(where, f"{name} axis is not regular and increasing")
    on = hm.on_part
    if not on.any():
        raise InkSliceError(where, "has no cell with a height (nothing to mill)")
    if np.nanmin(hm.z) < FLOOR - 1e-9:
        raise InkSliceError(where, f"has heights below the base top (min {np.nanmin(hm.z):.3f} mm)")
    holes = interior_holes(on)
    if holes.any():
        j, i = np.argwhere(holes)[0]
        raise InkSliceError(
            where,
            f"has {int(holes.sum())} cells with no height inside the part "
            f"(first at x={hm.x[i]:.2f}, y={hm.y[j]:.2f} mm): fill the holes "
            "(re-scan or interpolate) first",
        )


def with_edges_kept(hm: HeightMap) -> HeightMap:
    """The map as the CAM mills it: each cell on the part's outline that is on its outer wall
    (source WALL) held no lower than its highest neighbour inside.

    Such a cell's height is where the wall passes its centre (surface/edges.py), somewhere
    between the base and the top; the wall's top edge lies within the cell. Followed down
    there, the cutter sweeps the slope between the cell and its neighbour inside and cuts
    that edge off: up to the whole wall's height (the stepped block's 12 mm tier, its hidden
    walls held at mid-height). Kept at the neighbour's height, it leaves at most that cell's
    strip of material outside the part instead."""
    if hm.source is None or not hm.on_part.any():
        return hm
    from ..surface.uncertainty import WALL

    edge = hm.outline & (hm.source == WALL)
    if not edge.any():
        return hm
    inside = ndimage.maximum_filter(
        np.where(hm.on_part & ~edge, hm.z, -np.inf), size=3, mode="constant", cval=-np.inf
    )
    z = np.where(edge & np.isfinite(inside), np.maximum(hm.z, inside), hm.z)
    return HeightMap(hm.x, hm.y, z, hm.sigma, hm.source)


class Sampler:
    """z(x, y) of a height map, piecewise linear on triangles, floor off the part. A map
    that says where its cells came from is read with its outer walls' cells kept at the
    edge (with_edges_kept)."""

    def __init__(self, hm: HeightMap, floor: float = FLOOR, edge_step: float | None = None):
        hm = with_edges_kept(hm)
        self.hm = hm
        self.edge_step = edge_step
        self.x0, self.y0 = float(hm.x[0]), float(hm.y[0])
        self.dx, self.dy = hm.spacing
        self.nx, self.ny = hm.x.size, hm.y.size
        self.floor = float(floor)
        z = hm.z
        # corners of each cell; a cell is on the part when all four are
        z00, z10, z01, z11 = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]
        cell_on = np.isfinite(z00) & np.isfinite(z10) & np.isfinite(z01) & np.isfinite(z11)
        self.cell_on = cell_on
        f = lambda a: np.where(cell_on, a, floor)
        self._g00, self._g10, self._g01, self._g11 = f(z00), f(z10), f(z01), f(z11)
        self._z00, self._z10, self._z01, self._z11 = (
            g.ravel() for g in (self._g00, self._g10, self._g01, self._g11)
        )
        # each cell's two triangles, interleaved (upper u >= v first): z = z00 + p P + q Q with
        # p = max(u, v), q = min(u, v); three takes instead of four, one triangle computed
        self._P = np.column_stack([self._z10 - self._z00, self._z01 - self._z00]).ravel()
        self._Q = np.column_stack([self._z11 - self._z10, self._z11 - self._z01]).ravel()

    @property
    def corner_grids(self):
        """Each cell's corner heights (z00, z10, z01, z11), floor on cells off the part."""
        return self._g00, self._g10, self._g01, self._g11

    @cached_property
    def cell_top(self):
        """Each cell's highest corner (floor off the part): no point of its triangles is higher."""
        return np.maximum(np.maximum(self._g00, self._g10), np.maximum(self._g01, self._g11))

    def _cell(self, x, y):
        fx = (np.asarray(x, float) - self.x0) / self.dx
        fy = (np.asarray(y, float) - self.y0) / self.dy
        # the far edges belong to the last cell (clipping before the floor is the same as after:
        # the bounds are whole numbers)
        inside = (fx >= 0) & (fy >= 0) & (fx <= self.nx - 1 + 1e-9) & (fy <= self.ny - 1 + 1e-9)
        ic = np.clip(fx, 0, self.nx - 2).astype(np.intp)
        jc = np.clip(fy, 0, self.ny - 2).astype(np.intp)
        return fx - ic, fy - jc, ic, jc, inside

    def z(self, x, y):
        # the most called function of the CAM (the drop-cutter's and the planner's ring scans)
        u, v, i, j, inside = self._cell(x, y)
        k = j * (self.nx - 1) + i
        lower = u < v
        kk = 2 * k + lower
        out = self._z00[k] + np.maximum(u, v) * self._P[kk] + np.minimum(u, v) * self._Q[kk]
        return np.where(inside, out, self.floor)

    def z_grid(self, xs, ys):
        """z on the lattice xs x ys, shape (len(ys), len(xs)); cheaper than z() on a mesh."""
        xs = np.asarray(xs, float)
        ys = np.asarray(ys, float)
        u, _, i, _, in_x = self._cell(xs, np.full(xs.shape, self.y0))
        _, v, _, j, in_y = self._cell(np.full(ys.shape, self.x0), ys)
        # two plain takes are ~8x faster than one broadcast fancy index (which was most
        # of a planner's candidate pass); the one that keeps less goes first (a pass end's
        # few columns on many rows: rows first copied whole map rows, 7 s of 9 s)
        if (self.ny - 1) * i.size < j.size * (self.nx - 1):
            take = lambda g: g.take(i, axis=1).take(j, axis=0)
        else:
            take = lambda g: g.take(j, axis=0).take(i, axis=1)
        z00, z10, z01, z11 = (take(g) for g in (self._g00, self._g10, self._g01, self._g11))
        U, V = u[None, :], v[:, None]
        out = np.where(
            U >= V, z00 + U * (z10 - z00) + V * (z11 - z10), z00 + V * (z01 - z00) + U * (z11 - z01)
        )
        return np.where(in_y[:, None] & in_x[None, :], out, self.floor)

    def on_part(self, x, y):
        u, v, i, j, inside = self._cell(x, y)
        return inside & self.cell_on[j, i]

    def part_distance(self, x, y):
        """How far (mm) a point is outside the footprint (the union of the on-part cells); 0 inside.

        Exact: the margins compared with it are up to a cutter's radius, and a position kept
        a cell further (a cell-centre distance transform was) lets the cutter leave the part:
        on the daemon's 1.2 mm map of a sphere, whose wall stands 6-9 mm at the outline, a
        ball's tip dropped from 6.0 to the base between two positions 0.02 mm apart, and the
        move cut 1.08 mm into the wall.
        """
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        out = np.zeros(np.broadcast_shapes(x.shape, y.shape))
        x, y = np.broadcast_to(x, out.shape), np.broadcast_to(y, out.shape)
        off = ~self.on_part(x, y)
        if off.any():
            out[off] = self._outline_distance(x[off], y[off])
        return out

    def _outline_distance(self, x, y):
        """Exact distance from points off the part to the nearest on-part cell (a rectangle)."""
        tree, centres = self._rim_cells
        hx, hy = 0.5 * self.dx, 0.5 * self.dy
        # the nearest cell is among those whose centre is within the nearest centre's
        # distance plus half a cell's diagonal
        dc, _ = tree.query(np.column_stack([x, y]))
        hits = tree.query_ball_point(np.column_stack([x, y]), dc + np.hypot(hx, hy) + 1e-9)
        count = np.fromiter((len(h) for h in hits), int, len(hits))
        cell = np.concatenate(hits).astype(int)
        point = np.repeat(np.arange(len(hits)), count)
        gx = np.maximum(np.abs(x[point] - centres[cell, 0]) - hx, 0.0)
        gy = np.maximum(np.abs(y[point] - centres[cell, 1]) - hy, 0.0)
        return np.minimum.reduceat(np.hypot(gx, gy), np.cumsum(count) - count)

    @cached_property
    def _rim_cells(self):
        """A k-d tree of the centres of the on-part cells beside an off-part one, and those centres."""
        on = self.cell_on
        inner = ndimage.binary_erosion(np.pad(on, 1), np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool))
        j, i = np.nonzero(on & ~inner[1:-1, 1:-1])
        centres = np.column_stack([self.x0 + (i + 0.5) * self.dx, self.y0 + (j + 0.5) * self.dy])
        return cKDTree(centres), centres

    @property
    def edges(self):
        """Segments (ax, ay, az, bx, by, bz) along the footprint's boundary, or None.

        Only when the sampler was made with `edge_step` (any value: it now only
        switches the edges on; the contacts are exact per segment).
        """
        if self.edge_step is None:
            return None
        if getattr(self, "_edges", None) is None:
            self._edges = self._edge_segments()
        return self._edges

    def _edge_segments(self):
        on = np.pad(self.cell_on, 1)
        z = np.where(np.isfinite(self.hm.z), self.hm.z, self.floor)
        X = self.x0 + self.dx * np.arange(self.nx)
        Y = self.y0 + self.dy * np.arange(self.ny)
        segs = []
        jj, ii = np.nonzero(self.cell_on)
        # (neighbour offset, start node offset, end node offset) per side of a cell;
        # along a side the triangles interpolate linearly between its two nodes
        for (dj, di), (a, b) in (
            ((-1, 0), ((0, 0), (0, 1))),
            ((1, 0), ((1, 0), (1, 1))),
            ((0, -1), ((0, 0), (1, 0))),
            ((0, 1), ((0, 1), (1, 1))),
        ):
            side = ~on[jj + 1 + dj, ii + 1 + di]
            j, i = jj[side], ii[side]
            segs.append(
                np.column_stack(
                    [
                        X[i + a[1]],
                        Y[j + a[0]],
                        z[j + a[0], i + a[1]],
                        X[i + b[1]],
                        Y[j + b[0]],
                        z[j + b[0], i + b[1]],
                    ]
                )
            )
        # steep sides inside the part too: a wall between two lattice rows is a
        # cliff for the lattice just like the outer edge (slope above 1, 45 deg)
        zz = np.where(np.isfinite(self.hm.z), self.hm.z, np.nan)
        for axis, step in ((1, self.dx), (0, self.dy)):
            dz = np.abs(np.diff(zz, axis=axis))
            j, i = np.nonzero(np.nan_to_num(dz, nan=0.0) > step)
            j2, i2 = (j, i + 1) if axis == 1 else (j + 1, i)
            segs.append(np.column_stack([X[i], Y[j], z[j, i], X[i2], Y[j2], z[j2, i2]]))
        segs = np.vstack(segs)
        return None if segs.size == 0 else segs

    def may_be_steep(self, x, y, reach, slope):
        """False where no central difference of z within `reach` of (x, y) can exceed `slope`.

        A bound from the triangles' own gradients (the larger |dz/dx| and
        |dz/dy| of any cell within reach, and a cliff wherever the part meets
        the floor or the lattice ends), so a caller can skip the points it
        clears: on sample 1's dome the polish's eight reads of z per point over
        a whole map (0.9 s) were all for points that are nowhere steep.
        """
        cells = int(np.ceil(reach / min(self.dx, self.dy))) + 2
        key = (cells, float(slope))
        cache = self.__dict__.setdefault("_steep_cache", {})
        if key not in cache:
            cache[key] = self._steep_cells(cells, slope)
        u, v, i, j, inside = self._cell(x, y)
        return cache[key][j, i] | ~inside

    def may_have_steep_faces(self, x, y, reach, slope):
        """Like may_be_steep, but only the part's own faces count, not the cliff where it meets
        the floor (the drop-cutter meets that exactly, as edges): for a position off the part,
        whose axis stands on the base, read at the nearest cell of the lattice."""
        cells = int(np.ceil(reach / min(self.dx, self.dy))) + 2
        key = ("faces", cells, float(slope))
        cache = self.__dict__.setdefault("_steep_cache", {})
        if key not in cache:
            cache[key] = self._steep_cells(cells, slope, cliffs=False)
        u, v, i, j, inside = self._cell(x, y)
        return cache[key][j, i]

    def _steep_cells(self, cells, slope, cliffs=True):
        g00, g10, g01, g11 = self._g00, self._g10, self._g01, self._g11
        bx = np.maximum(np.abs(g10 - g00), np.abs(g11 - g01)) / self.dx
        by = np.maximum(np.abs(g11 - g10), np.abs(g01 - g00)) / self.dy
        on = self.cell_on
        # the cliff where the part meets the floor, inside the lattice and at its border
        cliff = on != ndimage.binary_erosion(on, np.ones((3, 3), bool), border_value=0)
        cliff |= ndimage.binary_dilation(cliff, np.ones((3, 3), bool)) | (
            ~on & ndimage.binary_dilation(on, np.ones((3, 3), bool))
        )
        if cliffs:
            bx, by = np.where(cliff, np.inf, bx), np.where(cliff, np.inf, by)
        else:
            bx, by = np.where(on, bx, 0.0), np.where(on, by, 0.0)
        size = 2 * cells + 1
        bx = ndimage.maximum_filter(bx, size=size, mode="nearest")
        by = ndimage.maximum_filter(by, size=size, mode="nearest")
        return np.hypot(bx, by) > slope

    @property
    def bounds(self):
        """(xmin, xmax, ymin, ymax) of the footprint's cells."""
        jj, ii = np.nonzero(self.cell_on)
        return (
            self.x0 + self.dx * ii.min(),
            self.x0 + self.dx * (ii.max() + 1),
            self.y0 + self.dy * jj.min(),
            self.y0 + self.dy * (jj.max() + 1),
        )

    def footprint_extent(self, e):
        """(lowest, highest) of e . p over the corners of the footprint's cells (a point beyond
        lies in no cell of the part); (-inf, inf) for an empty footprint."""
        jj, ii = np.nonzero(self.cell_on)
        if ii.size == 0:
            return -np.inf, np.inf
        cx = self.x0 + self.dx * np.concatenate([ii, ii + 1, ii, ii + 1])
        cy = self.y0 + self.dy * np.concatenate([jj, jj, jj + 1, jj + 1])
        t = cx * e[0] + cy * e[1]
        return float(t.min()), float(t.max())

    @property
    def z_max(self):
        return float(np.nanmax(self.hm.z))
