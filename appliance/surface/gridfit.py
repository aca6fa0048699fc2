"""The regularised grid fit on the lattice: the sparse least-squares problem.

The fit (gridfit / ANUDEM style) solves, on the lattice nodes over the part,
    min  sum_points (bilinear z(p) - z_p)^2 + w_cell sum_nodes (z - z_fe)^2
         + lambda * integral (z_xx^2 + 2 z_xy^2 + z_yy^2) dA
as a sparse least-squares problem (normal equations, SuperLU). The thin-plate
term reproduces any quadric exactly, so a cap with no data above the highest
waterline is continued as the paraboloid its neighbours imply.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.linalg import cg, spsolve

from .lattice import Lattice
from .slices import Slice

DIRECT_MAX = 12000  # unknowns up to which the fit is solved directly (SuperLU), else by CG


def point_data(slices: list[Slice], spacing_mm: float):
    """Non-wall waterline points thinned to about `spacing_mm` along each loop."""
    xs, zs = [], []
    for s in slices:
        if s.empty:
            continue
        keep = ~s.wall
        seg = np.hypot(*(s.P[s.nxt] - s.P).T)
        # thin by arc length: keep a point each time the running length passes a multiple
        run = np.cumsum(seg)
        bucket = np.floor(run / max(spacing_mm, 1e-9)).astype(np.int64)
        first_of_bucket = np.r_[True, bucket[1:] != bucket[:-1]]
        keep &= first_of_bucket
        xs.append(s.P[keep])
        zs.append(s.z[keep])
    if not xs:
        return np.zeros((0, 2)), np.zeros(0)
    return np.vstack(xs), np.concatenate(zs)


def stencil_rows(index: np.ndarray, stencils) -> sp.csr_matrix:
    """One row per lattice position where a stencil's nodes are all unknowns.

    index: (ny, nx) unknown number of each node, -1 where the node is not one;
    stencils: [(scale, [(dj, di, coefficient), ...]), ...]. The rows of all the
    stencils are stacked: R.T @ R is then the quadratic form of their sum of squares.
    """
    ny, nx = index.shape
    n = int(index.max()) + 1
    rows, cols, vals = [], [], []
    r = 0
    for scale, stencil in stencils:
        dj = [s[0] for s in stencil]
        di = [s[1] for s in stencil]
        j0, j1 = -min(dj), ny - max(dj)
        i0, i1 = -min(di), nx - max(di)
        ids = [index[j0 + a : j1 + a, i0 + b : i1 + b] for a, b in zip(dj, di)]
        ok = np.all([m >= 0 for m in ids], axis=0)
        m = int(ok.sum())
        for (_, _, c), im in zip(stencil, ids):
            rows.append(np.arange(r, r + m))
            cols.append(im[ok])
            vals.append(np.full(m, c * scale))
        r += m
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r, n))


class FitProblem:
    """The lattice's unknowns (nodes over the part) and its smoothness operators."""

    def __init__(self, lat: Lattice, footprint: np.ndarray, margin: int = 2):
        self.lat = lat
        self.active = ndimage.binary_dilation(footprint, iterations=margin) if margin else footprint.copy()
        self.index = np.full(lat.shape, -1, np.int64)
        self.index[self.active] = np.arange(int(self.active.sum()))
        self.n = int(self.active.sum())
        self.R = self._smoothness()

    def _smoothness(self):
        """Thin-plate energy: integral of z_xx^2 + 2 z_xy^2 + z_yy^2 over the part."""
        hx, hy = self.lat.hx, self.lat.hy
        s = np.sqrt(hx * hy)
        R = stencil_rows(
            self.index,
            [
                (s / hx**2, [(0, -1, 1.0), (0, 0, -2.0), (0, 1, 1.0)]),
                (s / hy**2, [(-1, 0, 1.0), (0, 0, -2.0), (1, 0, 1.0)]),
                (s * np.sqrt(2) / (hx * hy), [(0, 0, 1.0), (0, 1, -1.0), (1, 0, -1.0), (1, 1, 1.0)]),
            ],
        )
        return (R.T @ R).tocsc()

    def third_order(self):
        """Integral of the squared third derivatives (z_xxx^2 + 3 z_xxy^2 + 3 z_xyy^2 + z_yyy^2):
        zero on any quadric, so it bends a field only where its curvature changes."""
        R = self.third_order_rows()
        return (R.T @ R).tocsc()

    def third_order_rows(self):
        """The rows R of third_order (R.T @ R): one third difference each, scaled."""
        hx, hy = self.lat.hx, self.lat.hy
        s = np.sqrt(hx * hy)
        d3 = (-1.0, 3.0, -3.0, 1.0)
        d2, d1 = (1.0, -2.0, 1.0), (-1.0, 1.0)
        R = stencil_rows(
            self.index,
            [
                (s / hx**3, [(0, k, c) for k, c in enumerate(d3)]),
                (s / hy**3, [(k, 0, c) for k, c in enumerate(d3)]),
                (
                    s * np.sqrt(3) / (hx**2 * hy),
                    [(a, b, ca * cb) for a, ca in enumerate(d1) for b, cb in enumerate(d2)],
                ),
                (
                    s * np.sqrt(3) / (hx * hy**2),
                    [(a, b, ca * cb) for a, ca in enumerate(d2) for b, cb in enumerate(d1)],
                ),
            ],
        )
        return R

    def gradient(self):
        """(Dx, Dy): the slope of the field at each unknown, central where both
        neighbours are unknowns, one-sided where only one is."""
        ops = []
        J, I = np.nonzero(self.active)
        me = self.index[J, I]
        for axis, h in ((1, self.lat.hx), (0, self.lat.hy)):

            def neighbour(d, axis=axis):
                jj, ii = (J + d, I) if axis == 0 else (J, I + d)
                ok = (jj >= 0) & (ii >= 0) & (jj < self.lat.shape[0]) & (ii < self.lat.shape[1])
                out = np.full(J.size, -1)
                out[ok] = self.index[jj[ok], ii[ok]]
                return out

            lo, hi = neighbour(-1), neighbour(1)
            rows, cols, vals = [], [], []
            for sel, terms in (
                ((lo >= 0) & (hi >= 0), ((lo, -0.5), (hi, 0.5))),
                ((lo < 0) & (hi >= 0), ((me, -1.0), (hi, 1.0))),
                ((lo >= 0) & (hi < 0), ((lo, -1.0), (me, 1.0))),
            ):
                for col, c in terms:
                    rows.append(me[sel])
                    cols.append(col[sel])
                    vals.append(np.full(int(sel.sum()), c / h))
            ops.append(
                sp.csr_matrix(
                    (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                    shape=(self.n, self.n),
                )
            )
        return tuple(ops)

    def data_rows(self, pts, z, weight=1.0):
        """Bilinear rows for scattered points; points whose cell is not all active are dropped."""
        lat = self.lat
        fi, fj = lat.to_index(pts)
        i0 = np.floor(fi).astype(np.int64)
        j0 = np.floor(fj).astype(np.int64)
        ny, nx = lat.shape
        inb = (i0 >= 0) & (j0 >= 0) & (i0 < nx - 1) & (j0 < ny - 1)
        i0, j0, fi, fj, z = i0[inb], j0[inb], fi[inb], fj[inb], z[inb]
        tx, ty = fi - i0, fj - j0
        ids = [self.index[j0, i0], self.index[j0, i0 + 1], self.index[j0 + 1, i0], self.index[j0 + 1, i0 + 1]]
        ok = np.all([m >= 0 for m in ids], axis=0)
        w = [(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty]
        m = int(ok.sum())
        rows = np.tile(np.arange(m), 4)
        cols = np.concatenate([a[ok] for a in ids])
        vals = np.concatenate([b[ok] for b in w]) * np.sqrt(weight)
        A = sp.csr_matrix((vals, (rows, cols)), shape=(m, self.n))
        return A, z[ok] * np.sqrt(weight)

    def node_rows(self, zgrid, weight):
        sel = self.active & np.isfinite(zgrid)
        cols = self.index[sel]
        m = cols.size
        A = sp.csr_matrix((np.full(m, np.sqrt(weight)), (np.arange(m), cols)), shape=(m, self.n))
        return A, zgrid[sel] * np.sqrt(weight)

    def gap_fill(self, z_nodes):
        """The lambda -> 0 limit: data nodes kept, every gap filled by the thin plate.

        Only the gap nodes are unknowns, so the direct solve stays small; it is
        also the start for the smoothing solve below.
        """
        have = self.active & np.isfinite(z_nodes)
        zd = np.where(have, z_nodes, 0.0)[self.active]
        gap = ~have[self.active]
        out = np.full(self.lat.shape, np.nan)
        full = zd.copy()
        if gap.any():
            R = self.R.tocsr()
            Ruu = R[gap][:, gap].tocsc()
            rhs = -(R[gap][:, ~gap] @ zd[~gap])
            Ruu = Ruu + sp.identity(int(gap.sum()), format="csc") * 1e-9 * max(abs(Ruu).max(), 1.0)
            full[gap] = spsolve(Ruu, rhs, permc_spec="MMD_AT_PLUS_A")
        out[self.active] = full
        return out

    def solve(self, blocks, lam, start=None, maxiter=150):
        """Minimise the data misfit + lam * thin-plate energy: directly up to DIRECT_MAX
        unknowns, else by conjugate gradients from the gap-filled `start` (node heights, NaN
        where none): the data pin almost every node, so that start is close and a few
        hundred Jacobi-preconditioned steps suffice. (The direct solve needs no start: the
        gap fill, a solve of its own, was 7 of the fit's 14 on the demo's scan.)"""
        A = sp.vstack([b[0] for b in blocks]).tocsr()
        b = np.concatenate([b[1] for b in blocks])
        M = ((A.T @ A) + lam * self.R).tocsr()
        M = (M + sp.identity(self.n, format="csr") * 1e-9).tocsr()
        rhs = A.T @ b
        if self.n <= DIRECT_MAX:
            sol = spsolve(M.tocsc(), rhs)
        else:
            x0 = None if start is None else self.gap_fill(start)[self.active]
            diag = M.diagonal()
            pre = sp.diags(1.0 / np.where(diag > 0, diag, 1.0))
            sol, _ = cg(M, rhs, x0=x0, rtol=1e-8, maxiter=maxiter, M=pre)
        z = np.full(self.lat.shape, np.nan)
        z[self.active] = sol
        return z
