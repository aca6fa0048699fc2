"""First-exposure heights: where each lattice node came out of the ink.

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

The two-level rule is the straight line; with more levels around the node
the polynomial through them follows a curved top. A refinement frame whose
waterline runs beside its neighbour's (within half a lattice cell) is left
out of that polynomial (_apart).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..forks import ITEM_POINTS, each_in_parts
from .lattice import Lattice, exposed_mask
from .slices import Slice, polyline_distance


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


def _apart(S, ok, c_in, levels, tol):
    """`ok` without the waterlines of finer steps that pass within `tol` of the one next
    nearer the node's bracket (per row, outwards from the bracket on each side): a frame
    less than half the bracket's step from its neighbour (a refinement frame) whose
    waterline runs beside that neighbour's.

    As far as the lattice can tell the two are one curve at two heights, a wall or a rim
    between them, not a slope the polynomial can follow: a refinement frame 0.08 mm below
    its step whose waterline runs 0.04 mm beside the step's along a wall foot swings the
    cubic by a whole step (the harsh ring's outer foot: 8.63 where the frames bracket
    7.31..8.63 and the straight line gives 7.60). Waterlines of full steps close together
    are a steep flank, which the polynomial follows (a sphere's side near its rim)."""
    ok = ok.copy()
    rows = np.arange(S.shape[0])
    n = S.shape[1]
    lo, hi = np.clip(c_in, 0, n - 1), np.clip(c_in - 1, 0, n - 1)
    fine = 0.5 * np.abs(levels[hi] - levels[lo])  # half the bracket's step, per row
    for start, step in ((c_in, 1), (c_in - 1, -1)):
        # `last`: the usable waterline next nearer the bracket (`have`: there is one yet; a
        # column with no level curve holds no distance to compare with)
        last = np.clip(start, 0, n - 1)
        have = (start >= 0) & (start < n) & ok[rows, last]
        for off in range(1, n):
            col = start + step * off
            c = np.clip(col, 0, n - 1)
            use = (col >= 0) & (col < n) & ok[rows, c]
            close = (
                use
                & have
                & (np.abs(S[rows, c] - S[rows, last]) < tol)
                & (np.abs(levels[c] - levels[last]) < fine)
            )
            ok[rows[close], c[close]] = False
            last = np.where(use & ~close, c, last)
            have |= use
    return ok


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
    for k in range(K - 1, -1, -1):
        # the raster takes in a node the waterline passes near: on a slope that is a level
        # early, beside a wall the wall's whole height (a boss's 12 mm: the nodes beside it
        # came out with its top). There the exact side decides, at a wall's foot and at a top
        # edge put back from a silhouette alike (behind such an edge the node's height is
        # not the frames' to give: inkbounds.behind_faces)
        m = exposed_mask(lat, slices[k], exact_edges="walls")
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
    # the nodes grouped by the level they came out at, once (stable: lattice order in each)
    counts = np.bincount(first.ravel(), minlength=K + 1)
    by_level = np.split(np.argsort(first.ravel(), kind="stable"), np.cumsum(counts)[:-1])
    ks = [k for k in range(top, K) if counts[k]]

    def heights(i):  # of the nodes that came out at level ks[i]
        idx = by_level[ks[i]]
        q = np.column_stack([X.ravel()[idx], Y.ravel()[idx]])
        return _came_out_at(slices, ks[i], top, q, on_outline.ravel()[idx], hmax, order)

    # each level's nodes need nothing of the others': on the cores where forking is allowed
    for k, zz in zip(ks, each_in_parts(heights, counts[ks] + ITEM_POINTS)):
        z.ravel()[by_level[k]] = zz
    return z, first, footprint


def _came_out_at(slices, k, top, q, rim, hmax, order):
    """Heights of the nodes q that came out at level k (rim: those on the outline), NaN where
    the waterlines do not place one (first_exposure)."""
    K = len(slices)
    lo_span = order // 2
    # one more level uphill than the rule needs: where the lower waterlines are
    # walls the node is extrapolated from the uphill ones alone
    js = [j for j in range(k - (order - lo_span) - 1, k + lo_span) if top <= j < K]
    if k == top:  # the cap: every neighbouring waterline lies downhill
        js = [j for j in range(top, min(K, top + max(order - 1, 2)))]
    S = np.zeros((len(q), len(js)))
    Z = np.zeros_like(S)
    ok = np.zeros(S.shape, bool)
    within = np.zeros(S.shape, bool)  # the node inside the waterline, walls and all
    for c, j in enumerate(js):
        sl = slices[j]
        sd, i = polyline_distance(sl, q, signed=True)
        # far from the waterline the raster mask's side is the robust one; near it
        # (within a node and a half) the exact side of the nearest segment
        in_mask = k <= j  # every node here came out at k
        far_node = np.abs(sd) > 1.5 * hmax
        side = np.where(far_node | rim, in_mask, sd >= 0)
        within[:, c] = side
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
    # inside by the whole waterline: a frame whose waterline is all wall has no level curve
    # and no distance, and read as a distance of 0 it put the bracket's floor at its level,
    # far above (steps' boss top at 22.6 mm came out at the 25 mm frame's level)
    c_in = np.where(within.any(axis=1), np.argmax(within, axis=1), len(js))
    zmin = np.where(c_in < len(js), levels[np.minimum(c_in, len(js) - 1)], -np.inf)
    zmax = np.where(c_in > 0, levels[np.maximum(c_in - 1, 0)], np.inf)
    rise = np.where(ok, Z - levels, 0.0)  # meniscus-corrected heights widen it
    zmin = zmin + np.minimum(rise.min(axis=1), 0)
    zmax = zmax + np.maximum(rise.max(axis=1), 0)
    raw = _lagrange_at_zero(S, Z, _apart(S, ok, c_in, levels, 0.5 * hmax))
    zz = np.clip(raw, zmin, zmax)
    # a polynomial that leaves its bracket is not to be trusted: let the fit decide
    zz[np.abs(raw - zz) > 0.25 * (zmax - zmin)] = np.nan
    zz[~good] = np.nan
    # nor one that lands far outside the levels it was made from (near-equal distances
    # to two waterlines blow the Lagrange weights up)
    spread = levels.max() - levels.min()
    zz[~np.isfinite(raw) | (raw < levels.min() - spread) | (raw > levels.max() + spread)] = np.nan
    return zz
