"""The cutter's opening of the design: what an infinitely fine stepover leaves.

Dropping the cutter at every position of a lattice gives the tip heights;
lowering the stock by the cutter at all of them (a grey erosion of the tips
with the cutter's profile) gives the opening. Where it stands above the
design the cutter cannot reach at all (a concave region tighter than it, the
wall of a step, the top of a dome under a flat bottom): no stepover removes
that, so the scallop is measured only where the opening comes within a
reach tolerance of the design, and above the opening's own residue there.

The verification (millsim.report) and the stepover planner (zigzag.py) read
the same opening through the same functions, so the planner holds the
scallop the verification measures, not an approximation of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .contact import STEEP, plane_contact, polish, surface_gradient
from .cutters import Cutter
from .dropcutter import CACHE_ELEMENTS, disc_offsets, drop_grid
from .sampling import Sampler

REACH_TOL = 0.005  # mm: a cell is reachable when the opening is within this of the design


def opening(sampler: Sampler, cutter: Cutter, x0, y0, nx, ny, d):
    """The design opened by the cutter on the lattice x0 + i d, y0 + j d; shape (ny, nx)."""
    # the tips a program has (contact.py): the lattice alone stands low on steep
    # faces (0.02-0.03 mm for a 1 mm ball on sample 4's 80-degree faces) and, for a
    # flat end, by slope x its shortfall from the rim everywhere, and would call a
    # strip reachable that no tool position reaches
    # in bands of rows: the drop's and the polish's temporaries over a whole map
    # at 0.1 mm were 220 MB, half of a finishing plan's peak
    tip = np.empty((ny, nx))
    xs = x0 + d * np.arange(nx)
    for j0, j1 in _bands(ny, nx):
        X, Y = np.meshgrid(xs, y0 + d * np.arange(j0, j1))
        tip[j0:j1] = polish(
            sampler,
            cutter,
            X,
            Y,
            drop_grid(sampler, cutter, x0, y0 + d * j0, nx, j1 - j0, d),
            d,
            off_part=False,
        )
    out = _erode(tip, cutter, d)
    if cutter.kind == "flat":
        np.minimum(out, _rim_minimum(tip, cutter.radius / d), out=out)
        np.minimum(out, _side_ends(tip, cutter.radius / d), out=out)
    else:
        for j0, j1 in _bands(ny, nx):
            X, Y = np.meshgrid(xs, y0 + d * np.arange(j0, j1))
            _polish_minimum(sampler, cutter, tip, out, X, Y, d, rows=slice(j0, j1))
    return out


def _bands(ny, nx, cells=40_000):
    # 150 k nodes a band held the drop's edge pairs and the polish's temporaries: 70 MB of
    # the daemon's toolpath peak on a sphere's coarse map
    rows = max(1, cells // max(nx, 1))
    return [(j0, min(j0 + rows, ny)) for j0 in range(0, ny, rows)]


def _erode(tip, cutter, d):
    """min over the disc's lattice offsets u of tip(p + u) + h(|u|); inf off the lattice.

    h is symmetric in both offsets, so rows b and -b are folded first, then
    columns a and -a: three operations per quarter-disc offset instead of
    eight per four offsets. Single precision relative to the lowest tip halves
    the memory traffic (the whole cost: 25 s -> 2.5 s on a 100 x 100 mm map
    at 0.1 mm); a part 100 mm tall still resolves 1e-5 mm. The lattice is
    eroded in bands of rows whose arrays stay in cache through the ~1450
    operations (the whole map at once streamed 4 MB arrays from memory each
    time: 1.1 -> 0.5 s).
    """
    groups, m = disc_offsets(cutter, d)
    quarter = [
        (b, [(a, np.float32(h)) for a, h in zip(av.tolist(), hv.tolist()) if a >= 0]) for b, av, hv in groups
    ]
    ny, nx = tip.shape
    finite = np.isfinite(tip)
    ref = float(np.min(tip[finite])) if finite.any() else 0.0
    pad = np.full((ny + 2 * m, nx + 2 * m), np.inf, np.float32)
    pad[m : m + ny, m : m + nx] = tip - ref
    out = np.full(tip.shape, np.inf, np.float32)
    band = max(1, CACHE_ELEMENTS // max(nx, 1))
    tmp = np.empty((band, nx), np.float32)
    rows = np.empty((band, nx + 2 * m), np.float32)
    for j0 in range(0, ny, band):
        j1 = min(j0 + band, ny)
        o, t, rw = out[j0:j1], tmp[: j1 - j0], rows[: j1 - j0]
        for b, offsets in quarter:
            if b == 0:
                rw[...] = pad[m + j0 : m + j1]
            else:
                np.minimum(pad[m + j0 + b : m + j1 + b], pad[m + j0 - b : m + j1 - b], out=rw)
            for a, h in offsets:
                if a == 0:
                    np.add(rw[:, m : m + nx], h, out=t)
                else:
                    np.minimum(rw[:, m + a : m + a + nx], rw[:, m - a : m - a + nx], out=t)
                    np.add(t, h, out=t)
                np.minimum(o, t, out=o)
    return out.astype(np.float64) + ref


_PATTERN = np.stack([a.ravel() for a in np.meshgrid(np.arange(-2, 3), np.arange(-2, 3))])


def _polish_minimum(sampler, cutter, tip, out, X, Y, d, chunk=2_500, rows=None):
    """Lower `out` (in place) on steep faces to nearer the continuous minimum.

    The erosion takes the min of tip(p + u) + h(|u|) over lattice offsets u;
    near the minimum that function curves like h'' = 1 / (rc cos^3), which
    on a steep face is large (526 /mm for a 1 mm ball on an 81-degree face),
    so the lattice misses the minimum by up to h'' (d / sqrt 2)^2 / 2: 0.05 mm
    at d = 0.02 mm on sample 4, where cells the cutter reaches were called
    unreachable at one lattice and reachable at another. Where the design is
    steep the minimum is searched near where the cutter touching the cell
    stands (a plane of the local slope: the axis downhill of the contact),
    with shrinking 5 x 5 patterns (d, d/4, d/16 apart), the tips read
    bilinearly between nodes (they are smooth there: an offset surface).
    """
    ny, nx = tip.shape
    rows = slice(0, ny) if rows is None else rows
    # (X, Y) are the lattice's rows `rows`; tip and out are the whole lattice's
    lx0, ly0 = X[0, 0], Y[0, 0] - d * rows.start
    flat_out = out[rows].reshape(-1)
    near = np.flatnonzero(sampler.may_be_steep(X.ravel(), Y.ravel(), d / 2, STEEP) & np.isfinite(flat_out))
    gx, gy = np.zeros(flat_out.size), np.zeros(flat_out.size)
    gx[near], gy[near] = surface_gradient(sampler, X.ravel()[near], Y.ravel()[near], d / 2)
    idx = near[np.hypot(gx[near], gy[near]) > STEEP]
    R = cutter.radius
    for s in range(0, idx.size, chunk):
        k = idx[s : s + chunk]
        ux, uy = plane_contact(cutter, gx[k], gy[k])
        cx, cy = -ux, -uy  # cell to axis: downhill of the contact
        px, py = X.ravel()[k], Y.ravel()[k]
        best = flat_out[k]
        sp = d
        for _ in range(3):
            ox = cx[:, None] + sp * _PATTERN[0][None, :]
            oy = cy[:, None] + sp * _PATTERN[1][None, :]
            r = np.hypot(ox, oy)
            fi = (px[:, None] + ox - lx0) / d
            fj = (py[:, None] + oy - ly0) / d
            inside = (r <= R) & (fi >= 0) & (fi <= nx - 1) & (fj >= 0) & (fj <= ny - 1)
            t = ndimage.map_coordinates(tip, [fj.ravel(), fi.ravel()], order=1, mode="nearest").reshape(
                fi.shape
            )
            f = np.where(inside, t + cutter.profile(np.minimum(r, R)), np.inf)
            j = np.argmin(f, axis=1)
            rows = np.arange(k.size)
            best = np.minimum(best, f[rows, j])
            cx, cy = ox[rows, j], oy[rows, j]
            sp /= 4
        flat_out[k] = best


_RIM = 64


def _rim_minimum(tip, r, chunk=8):
    """min of the tips, bilinearly interpolated, on the circle of radius r (lattice units)
    around every node; inf where the circle leaves the lattice.

    A flat end's bottom is level (h = 0 out to R), so the opening at a cell is
    the lowest tip within R of it, and on a slope that lies on the circle of
    radius R, downhill. The lattice disc stops short of that circle by up to a
    lattice step, which leaves the opening |grad tip| x d high (0.004 mm on a
    0.09 slope at 0.05 mm): whether a cell counts as reachable then depended on
    the lattice. Tips vary smoothly between nodes, so interpolating them on the
    circle itself errs only to second order; 64 angles leave at most R x
    |grad| x (1 - cos(pi / 64)), 3e-4 mm for a 6 mm end on a 0.09 slope.
    """
    ny, nx = tip.shape
    J, I = np.mgrid[0:ny, 0:nx].astype(float)
    out = np.full(tip.shape, np.inf)
    ang = 2 * np.pi * np.arange(_RIM) / _RIM
    for k in range(0, _RIM, chunk):
        for th in ang[k : k + chunk]:
            fi, fj = I + r * np.cos(th), J + r * np.sin(th)
            inside = (fi >= 0) & (fi <= nx - 1) & (fj >= 0) & (fj <= ny - 1)
            val = ndimage.map_coordinates(tip, [fj, fi], order=1, mode="nearest")
            np.minimum(out, np.where(inside, val, np.inf), out=out)
    return out


@dataclass
class Opening:
    """An opening on a lattice, read anywhere by bilinear interpolation."""

    cutter: Cutter
    x0: float
    y0: float
    d: float
    z: np.ndarray

    @classmethod
    def over(
        cls, sampler: Sampler, cutter: Cutter, d, x0=None, y0=None, x1=None, y1=None, pad=0.0, split=None
    ):
        """The opening on a lattice of spacing d from (x0, y0) to (x1, y1) (default: the footprint's
        bounds), with tool positions up to `pad` beyond them (whole steps of d): a program that
        runs off the outline onto the base reaches the rim from there. `split`: a forks.in_parts
        that computes it in parts of rows on the cores (each with a cutter's reach of rows
        beyond it, so a row's value is what the whole lattice gives it)."""
        bx0, bx1, by0, by1 = sampler.bounds
        x0 = bx0 if x0 is None else x0
        y0 = by0 if y0 is None else y0
        x1 = bx1 if x1 is None else x1
        y1 = by1 if y1 is None else y1
        # nodes up to the far bound and `pad` past it, no further (like the simulation's
        # stock): a position further out is one no program has
        k = int(np.ceil(pad / d - 1e-9)) if pad > 0 else 0
        x0, y0, x1, y1 = x0 - k * d, y0 - k * d, x1 + k * d, y1 + k * d
        nx = np.arange(x0, x1 + d / 2, d).size
        ny = np.arange(y0, y1 + d / 2, d).size
        if split is None:
            return cls(cutter, float(x0), float(y0), float(d), opening(sampler, cutter, x0, y0, nx, ny, d))
        reach = int(np.ceil(cutter.radius / d)) + 2  # the erosion's and its polish's rows

        def rows(j0, j1):
            a, b = max(0, j0 - reach), min(ny, j1 + reach)
            return opening(sampler, cutter, x0, y0 + a * d, nx, b - a, d)[j0 - a : j1 - a]

        return cls(cutter, float(x0), float(y0), float(d), split(rows, np.ones(ny), np.concatenate))

    def at(self, X, Y):
        X, Y = np.asarray(X, float), np.asarray(Y, float)
        return ndimage.map_coordinates(
            self.z, [(Y - self.y0) / self.d, (X - self.x0) / self.d], order=1, mode="nearest"
        )

    def above(self, stock, design, X, Y, reach_tol=REACH_TOL):
        """(stock above the opening's residue, reachable) at points (X, Y) with heights `design`.

        In a reachable cell the opening may still stand up to reach_tol above
        the design (cells beside an edge the cutter rides on, concave regions
        just tighter than the cutter): that residue is the cutter's size, not
        the stepover's, so it is taken off. The lattice opening (a min over
        offsets d apart) can stand above the true one by up to h'' (d/sqrt2)^2
        / 2 = d^2 / (4 rc): only the residue beyond that is taken off, so no
        stock the stepover left is hidden (a flat end, h'' unbounded at its
        rim: none).
        """
        return self.above_at(stock, design, self.at(X, Y), reach_tol)

    def above_at(self, stock, design, op, reach_tol=REACH_TOL):
        """Like above(), with the opening already read at the points (`op`)."""
        reach = op - design
        rc = self.cutter.corner_radius
        slack = self.d**2 / (4 * rc) if rc > 0 else np.inf
        residue = np.clip(reach - slack, 0.0, reach_tol)
        return stock - design - residue, reach <= reach_tol


def _side_ends(tip, r):
    """min of the tips at the two ends of each lattice side's chord through the circle of
    radius r around every node (lattice units), interpolated along the side.

    Positions stop at the lattice's sides (the part's bounds), and there the
    lowest tip within R of a cell is often where the circle meets the side:
    the rim search above cannot see it (its points past the side do not
    count) and the lattice misses it by a step along the side.
    """
    ny, nx = tip.shape
    out = np.full(tip.shape, np.inf)
    J, I = np.mgrid[0:ny, 0:nx].astype(float)
    for line, dist, along, n in (
        (tip[:, 0], I, J, ny),
        (tip[:, -1], nx - 1 - I, J, ny),
        (tip[0, :], J, I, nx),
        (tip[-1, :], ny - 1 - J, I, nx),
    ):
        w = np.sqrt(np.maximum(r * r - dist * dist, 0.0))
        near = dist <= r
        for sign in (-1.0, 1.0):
            f = along + sign * w
            ok = near & (f >= 0) & (f <= n - 1)
            val = np.interp(np.where(ok, f, 0.0), np.arange(n), line)
            np.minimum(out, np.where(ok, val, np.inf), out=out)
    return out
