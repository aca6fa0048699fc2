"""First-exposure heights and the regularised grid fit, on one lattice.

First exposure: a lattice node's height is the level at which it first came
out of the ink. It is exposed at level k (inside that frame's waterline) and
still submerged at the level above, k - 1; between the two the top surface
crosses the node, and the signed distances to the two waterlines place it:
    z = z_lo + (z_hi - z_lo) * d_lo / (d_lo + d_hi).
This follows islands that merge and holes without any special case, because
it only asks "inside or outside" of each frame. The distances are to the
level-curve stretches of each waterline only (walls say nothing about where
the top crosses a level), so a node beside a wall is placed by the level
curves around it, and a node on the outline itself (the rim) is exposed at
the levels whose waterline runs along the wall through it.

The fit (gridfit / ANUDEM style) solves, on the lattice nodes over the part,
    min  sum_points (bilinear z(p) - z_p)^2 + w_cell sum_nodes (z - z_fe)^2
         + lambda * integral (z_xx^2 + 2 z_xy^2 + z_yy^2) dA
as a sparse least-squares problem (normal equations, SuperLU). The thin-plate
term reproduces any quadric exactly, so a cap with no data above the highest
waterline is continued as the paraboloid its neighbours imply.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.linalg import cg, spsolve
from scipy.spatial import cKDTree

from .slices import Slice, polyline_distance

_SHIFT = 8  # fillPoly sub-pixel bits
DIRECT_MAX = 12000  # unknowns up to which the fit is solved directly (SuperLU), else by CG


@dataclass
class Lattice:
    x: np.ndarray
    y: np.ndarray

    @property
    def hx(self):
        return float(self.x[1] - self.x[0])

    @property
    def hy(self):
        return float(self.y[1] - self.y[0])

    @property
    def shape(self):
        return (self.y.size, self.x.size)

    def to_index(self, pts):
        return (pts[:, 0] - self.x[0]) / self.hx, (pts[:, 1] - self.y[0]) / self.hy


def exposed_mask(lat: Lattice, sl: Slice, exact_edges: bool = False) -> np.ndarray:
    """Nodes inside the slice's waterline (even-odd over its loops: holes stay out)."""
    m = np.zeros(lat.shape, np.uint8)
    if sl.empty:
        return m.astype(bool)
    polys = []
    for lp in sl.loops:
        fi, fj = lat.to_index(lp)
        polys.append(np.round(np.column_stack([fi, fj]) * (1 << _SHIFT)).astype(np.int32))
    cv2.fillPoly(m, polys, 1, lineType=cv2.LINE_8, shift=_SHIFT)
    # fillPoly also paints the pixels the outline passes through: within a node or two of
    # the waterline the exact side of the nearest segment decides instead
    near = np.zeros(lat.shape, np.uint8)
    cv2.polylines(near, polys, True, 1, thickness=3, lineType=cv2.LINE_8, shift=_SHIFT)
    jj, ii = np.nonzero(near)
    if jj.size and exact_edges:
        sd, _ = polyline_distance(sl, np.column_stack([lat.x[ii], lat.y[jj]]), signed=True)
        m[jj, ii] = sd > 0
    return m.astype(bool)


def area_weights(lat: Lattice, slices: list[Slice], sub: int = 4) -> np.ndarray:
    """Each node's share of the part's footprint: the fraction of its cell (the node +-
    half a spacing) inside any of the slices' waterlines, from sub x sub samples per cell.

    The nodes inside a waterline undercount its area by a strip of about half a spacing
    all round (2.5 % of a 100 mm block on a 1 mm lattice); an emerged volume summed over
    them alone put the ink 0.13 mm off its true level. The footprint is the union of
    every frame's exposed region, not the lowest frame's alone: where the part has left
    the view in the lowest frames their loop cuts a chord across it (sample 2: 73 mm^2
    short, the lowest levels 0.15 mm high)."""
    off = (np.arange(sub) + 0.5) / sub - 0.5
    fine = Lattice(
        np.ravel(lat.x[:, None] + lat.hx * off[None, :]), np.ravel(lat.y[:, None] + lat.hy * off[None, :])
    )
    inside = np.zeros(fine.shape, bool)
    for sl in slices:
        if not sl.empty:
            inside |= exposed_mask(fine, sl, exact_edges=True)
    return inside.reshape(lat.y.size, sub, lat.x.size, sub).mean(axis=(1, 3))


def _lagrange_at_zero(s, z, ok):
    """Value at s = 0 of the polynomial through the usable (s_j, z_j), per row."""
    out = np.zeros(s.shape[0])
    for j in range(s.shape[1]):
        w = np.where(ok[:, j], 1.0, 0.0)
        for m in range(s.shape[1]):
            if m == j:
                continue
            den = s[:, j] - s[:, m]
            den = np.where(np.abs(den) < 1e-12, 1e-12, den)
            w = w * np.where(ok[:, m], (0.0 - s[:, m]) / den, 1.0)
        out += w * np.where(ok[:, j], z[:, j], 0.0)
    return out


def _passed_near(slices, q, start, stop, tol):
    """Per point: the first level k in [start, stop) whose waterline passes within `tol`,
    else `start`."""
    out = np.array(start, copy=True)
    todo = np.flatnonzero(stop > start + 1)
    found = np.zeros(len(q), bool)
    for k in range(int(start[todo].min()) if todo.size else 0, int(stop[todo].max()) if todo.size else 0):
        ask = todo[(start[todo] <= k) & (k < stop[todo]) & ~found[todo]]
        if ask.size == 0 or slices[k].empty:
            continue
        d, _ = polyline_distance(slices[k], q[ask])
        hit = ask[d <= tol]
        out[hit] = k
        found[hit] = True
    return out


def first_exposure(lat: Lattice, slices: list[Slice], footprint_tol_mm: float, order: int = 4):
    """-> (z_fe with NaN where no value, first index per node (len = never), footprint mask).

    Between the bracketing levels the node's height is interpolated along the
    signed distance to the waterlines: with `order` = 2 the linear rule above;
    with 3-4 the polynomial through the waterlines k-2 .. k+1 (skipping wall
    points), which is exact for a paraboloid and also continues the part's
    very top above the highest waterline (all distances then on one side).
    """
    K = len(slices)
    first = np.full(lat.shape, K, np.int32)
    masks = []
    for k in range(K - 1, -1, -1):
        m = exposed_mask(lat, slices[k])
        first[m] = k
    X, Y = np.meshgrid(lat.x, lat.y)
    footprint = first < K
    lowest = next(s for s in reversed(slices) if not s.empty)
    # nodes on the part's outline (the grid's edge on a block) sit on the wall itself:
    # count them in within a tolerance, their height comes from the fit
    near = ~footprint
    if near.any() and footprint_tol_mm > 0:
        q = np.column_stack([X[near], Y[near]])
        d, _ = polyline_distance(lowest, q)
        idx = np.flatnonzero(near.ravel())[d <= footprint_tol_mm]
        footprint.ravel()[idx] = True
    # nodes on the outline itself: every wall passes through them, no side is sure
    on_outline = np.zeros(lat.shape, bool)
    fq = np.column_stack([X[footprint], Y[footprint]])
    d_out, _ = polyline_distance(lowest, fq)
    on_outline[footprint] = d_out <= max(footprint_tol_mm, 1e-6)
    z = np.full(lat.shape, np.nan)
    visible = [k for k in range(K) if not slices[k].empty]
    top = visible[0]
    if on_outline.any():
        # a node on the outline is on the rim: it is out of the ink at every level whose
        # waterline runs through it (along the wall), under at the others
        oq = np.column_stack([X[on_outline], Y[on_outline]])
        fr = np.full(len(oq), K, np.int32)
        tol = max(footprint_tol_mm, 1e-6)
        for k in range(K - 1, top - 1, -1):
            d, _ = polyline_distance(slices[k], oq)
            fr[d <= tol] = k
        # a wall edge put back a little off the node can miss it: more than a level later
        # than the nodes just inside it is such a miss (a summit on the rim would otherwise
        # be clamped to the lowest level); it then comes out with the first of the levels
        # between whose waterline passes near it, or else with the nodes inside. On a steep
        # face the nodes inside came out levels earlier (a sphere's rim, 0.5 mm steps: its
        # outline nodes would be clamped 2 mm high)
        inner = np.where(on_outline, K, first)
        near = ndimage.minimum_filter(inner, size=3, mode="nearest")[on_outline]
        first[on_outline] = np.where(fr > near + 1, _passed_near(slices, oq, near, fr, 2 * tol), fr)
    hmax = max(lat.hx, lat.hy)
    for k in range(top, K):
        sel = first == k
        if not sel.any():
            continue
        q = np.column_stack([X[sel], Y[sel]])
        kq = first[sel]
        rim = on_outline[sel]
        lo_span = order // 2
        # one more level uphill than the rule needs: where the lower waterlines are
        # walls the node is extrapolated from the uphill ones alone
        js = [j for j in range(k - (order - lo_span) - 1, k + lo_span) if top <= j < K]
        if k == top:  # the cap: every neighbouring waterline lies downhill
            js = [j for j in range(top, min(K, top + max(order - 1, 2)))]
        S = np.zeros((len(q), len(js)))
        Z = np.zeros_like(S)
        ok = np.zeros(S.shape, bool)
        for c, j in enumerate(js):
            sl = slices[j]
            sd, i = polyline_distance(sl, q, signed=True)
            # far from the waterline the raster mask's side is the robust one; near it
            # (within a node and a half) the exact side of the nearest segment
            in_mask = kq <= j
            far_node = np.abs(sd) > 1.5 * hmax
            side = np.where(far_node | rim, in_mask, sd >= 0)
            # the distance that places the node is the one to the level curve: a wall
            # beside the node says nothing about where the top crosses the level
            cv = sl.level_curve()
            if cv.empty:
                continue
            d, ic = polyline_distance(cv, q)
            S[:, c] = np.where(side, d, -d)
            Z[:, c] = cv.z[ic]
            ok[:, c] = True
        below = ok & (S >= 0)
        n_ok = ok.sum(axis=1)
        if k == top:
            good = n_ok >= 2
        else:
            # bracketed: drop the extra uphill level; else extrapolate from >= 2 uphill ones
            two_sided = below.any(axis=1)
            extra = k - (order - lo_span) - 1
            if extra in js:
                ok[two_sided, js.index(extra)] = False
            n_ok = ok.sum(axis=1)
            # one-sided: trust it only as far out as the uphill waterlines are apart
            far = np.zeros(len(q), bool)
            up = ok & (S < 0)
            if (~two_sided).any():
                Sn = np.where(up, -S, np.inf)
                srt = np.sort(Sn, axis=1)
                if srt.shape[1] > 1:
                    with np.errstate(invalid="ignore"):
                        far = ~two_sided & ~(srt[:, 0] <= (srt[:, 1] - srt[:, 0]))
            good = (n_ok >= 2) & ~far
        # the node came out between the two bracketing levels (told by the exact signs,
        # the raster mask can be a node off): the answer must lie between them
        levels = np.array([slices[j].level for j in js])
        inside = S >= 0
        c_in = np.where(inside.any(axis=1), np.argmax(inside, axis=1), len(js))
        zmin = np.where(c_in < len(js), levels[np.minimum(c_in, len(js) - 1)], -np.inf)
        zmax = np.where(c_in > 0, levels[np.maximum(c_in - 1, 0)], np.inf)
        rise = np.where(ok, Z - levels, 0.0)  # meniscus-corrected heights widen it
        zmin = zmin + np.minimum(rise.min(axis=1), 0)
        zmax = zmax + np.maximum(rise.max(axis=1), 0)
        raw = _lagrange_at_zero(S, Z, ok)
        zz = np.clip(raw, zmin, zmax)
        # a polynomial that leaves its bracket is not to be trusted: let the fit decide
        zz[np.abs(raw - zz) > 0.25 * (zmax - zmin)] = np.nan
        zz[~good] = np.nan
        # nor one that lands far outside the levels it was made from (near-equal distances
        # to two waterlines blow the Lagrange weights up)
        spread = levels.max() - levels.min()
        zz[~np.isfinite(raw) | (raw < levels.min() - spread) | (raw > levels.max() + spread)] = np.nan
        z[sel] = zz
    return z, first, footprint


def flat_faces(lat: Lattice, slices: list[Slice], z_fe, first, far_mm: float, edge_mm: float = 0.0):
    """Heights for the nodes of faces that came out of the ink all at once.

    A face flatter than a level step per its width (a plateau, the top of a tier)
    is under the ink at one frame and wholly out at the next: no waterline crosses
    it, so first exposure has nothing to interpolate and the fit would extrapolate
    into it from whatever lies around - rims, walls - by millimetres of thin plate.
    What is sure is that it lies between the two levels. A node with no height yet
    farther than far_mm from the frame above's waterline (that frame did not show
    it, and not by a hair) and edge_mm inside its own (a node on the outline is on a
    rim, whose first exposure is not sure) gets that bracket;
    if it is also farther than far_mm from its own frame's level curve, the middle
    of it as its height. A cap above the highest frame gets neither unless a frame
    above showed nothing (its level then bounds the cap).
    -> (z_fe with the middle filled in, mask of those nodes, (lo, hi) per node: the
    bracket, NaN where none is sure)."""
    K = len(slices)
    z = z_fe.copy()
    mask = np.zeros(lat.shape, bool)
    lo = np.full(lat.shape, np.nan)
    hi = np.full(lat.shape, np.nan)
    # not the lowest frame's nodes: with no frame below it, a level curve there that
    # stays put from the frame above (a sculptured top flattening out towards the rim)
    # cannot be told from a wall, and the nodes beside it would look like a flat face
    lowest = max(k for k, s in enumerate(slices) if not s.empty)
    todo = ~np.isfinite(z_fe) & (first < lowest) & (first > 0)
    if not todo.any():
        return z, mask, (lo, hi)
    X, Y = np.meshgrid(lat.x, lat.y)
    for k in np.unique(first[todo]):
        sel = todo & (first == k)
        q = np.column_stack([X[sel], Y[sel]])
        d_curve, _ = polyline_distance(slices[k].level_curve(), q)
        d_above, _ = polyline_distance(slices[k - 1], q)
        d_own, _ = polyline_distance(slices[k], q)
        sure = (d_above > far_mm) & (d_own > edge_mm)
        idx = np.flatnonzero(sel.ravel())
        lo.ravel()[idx[sure]] = slices[k].level
        hi.ravel()[idx[sure]] = slices[k - 1].level
        mid = idx[sure & (d_curve > far_mm)]
        z.ravel()[mid] = 0.5 * (slices[k].level + slices[k - 1].level)
        mask.ravel()[mid] = True
    return z, mask, (lo, hi)


def tilt_crossed_faces(lat: Lattice, slices: list[Slice], z, mask, first, far_mm):
    """Faces that came out at once on both sides of one level curve are one tilted face.

    A nearly flat tier tilted by less than a level step over its width comes out in two
    pieces: the part above level L (under at the level above) and the part below it (under
    at L), with the level curve at L between them and no other. Its middles would put it
    flat at two heights a step apart, with a step at the curve. What the frames say: the
    face crosses L along the curve, and it is a plane (to what two brackets can tell) whose
    slope keeps each piece inside its bracket out to its farthest node - at most
    step / distance. Half that slope, away from the curve on each side, is the middle of
    what they allow (a plane at the largest slope and a flat face at L are both possible),
    as the middle of the bracket is for a face no curve crosses. z (flat_faces' middles)
    is changed in place; -> mask of the nodes so placed."""
    K = len(slices)
    tilted = np.zeros(lat.shape, bool)
    X, Y = np.meshgrid(lat.x, lat.y)
    touch = far_mm + 2.0 * max(lat.hx, lat.hy)  # a piece ends this near the curve it meets
    for k in range(2, K):
        below, above = mask & (first == k), mask & (first == k - 1)
        curve = slices[k - 1].level_curve()
        if not below.any() or not above.any() or curve.empty:
            continue
        # the stretch of curve between the two pieces (elsewhere the curve may run along a
        # rim or a wall foot: it says nothing about this face's slope)
        nodes = [np.column_stack([X[m], Y[m]]) for m in (below, above)]
        near = [cKDTree(q).query(curve.P, distance_upper_bound=touch)[0] <= touch for q in nodes]
        is_shared = near[0] & near[1]
        shared = curve.P[is_shared]
        if len(shared) == 0:
            continue
        tree = cKDTree(shared)

        def to_stretch(q):
            # along the polyline where its nearest vertex is on the stretch, else to the stretch's points
            d, i = polyline_distance(curve, q)
            return np.where(is_shared[i], d, tree.query(q)[0])

        L = slices[k - 1].level
        steps = (L - slices[k].level, slices[k - 2].level - L)
        # the pieces on either side, and which piece of one side faces which of the other
        # across the shared stretch (each shared point: the pieces nearest it)
        sides = []
        for side, q in zip((below, above), nodes):
            labels, _ = ndimage.label(side)
            d = to_stretch(q)
            nearest = labels[side][cKDTree(q).query(shared)[1]]
            sides.append((np.flatnonzero(side.ravel()), labels[side], d, nearest))
        pairs = set(zip(sides[0][3].tolist(), sides[1][3].tolist()))
        for a in {p[0] for p in pairs}:
            partners = sorted({p[1] for p in pairs if p[0] == a})
            lo_on = sides[0][1] == a
            hi_on = np.isin(sides[1][1], partners)
            slope = 0.5 * min(steps[0] / sides[0][2][lo_on].max(), steps[1] / sides[1][2][hi_on].max())
            for sign, (idx, _, d, _), on in ((-1.0, sides[0], lo_on), (1.0, sides[1], hi_on)):
                z.ravel()[idx[on]] = L + sign * slope * d[on]
                tilted.ravel()[idx[on]] = True
    return tilted


def occluded_nodes(lat: Lattice, seen: list[Slice], corrected: list[Slice]) -> np.ndarray:
    """Nodes that some frame showed covered by a face standing above the ink.

    Where a frame's waterline was a silhouette (slices.silhouettes), the camera saw
    the face's rim and the ink or part behind it was hidden; with the rims put back,
    the nodes between the rim as seen and the rim where it is are those it hid.
    Their heights come from the frames that saw them, or from the fit. `seen` are
    the slices as observed, `corrected` the same with their wall edges put back."""
    out = np.zeros(lat.shape, bool)
    for raw, cor in zip(seen, corrected):
        hidden = cor.hidden
        if raw.empty or hidden is None or not hidden.any():
            continue
        out |= exposed_mask(lat, raw) & ~exposed_mask(lat, cor)
    return out


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
        return (R.T @ R).tocsc()

    def gradient(self):
        """(Dx, Dy): the slope of the field at each unknown, central where both
        neighbours are unknowns, one-sided where only one is."""
        ops = []
        J, I = np.nonzero(self.active)
        me = self.index[J, I]
        for axis, h in ((1, self.lat.hx), (0, self.lat.hy)):

            def neighbour(d):
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

    def solve(self, blocks, lam, x0=None, maxiter=150):
        """Minimise the data misfit + lam * thin-plate energy by conjugate gradients,
        from `x0` (the gap-filled data): the data pin almost every node, so the
        start is close and a few hundred Jacobi-preconditioned steps suffice."""
        A = sp.vstack([b[0] for b in blocks]).tocsr()
        b = np.concatenate([b[1] for b in blocks])
        M = ((A.T @ A) + lam * self.R).tocsr()
        M = (M + sp.identity(self.n, format="csr") * 1e-9).tocsr()
        rhs = A.T @ b
        start = None if x0 is None else x0[self.active]
        if self.n <= DIRECT_MAX:
            sol = spsolve(M.tocsc(), rhs)
        else:
            diag = M.diagonal()
            pre = sp.diags(1.0 / np.where(diag > 0, diag, 1.0))
            sol, _ = cg(M, rhs, x0=start, rtol=1e-8, maxiter=maxiter, M=pre)
        z = np.full(self.lat.shape, np.nan)
        z[self.active] = sol
        return z


def fill_nearest(z):
    """z with its gaps (NaN) filled by the nearest value (all-NaN: zeros)."""
    nan = ~np.isfinite(z)
    if not nan.any() or nan.all():
        return np.where(nan, 0.0, z)
    _, (jj, ii) = ndimage.distance_transform_edt(nan, return_indices=True)
    return z[jj, ii]


def bilinear(lat: Lattice, zgrid, pts):
    """Bilinear interpolation of a lattice field at points (NaN outside)."""
    fi, fj = lat.to_index(pts)
    return ndimage.map_coordinates(zgrid, [fj, fi], order=1, mode="constant", cval=np.nan)
