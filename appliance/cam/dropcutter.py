"""Drop-cutter on a height map: the lowest tool-tip height that touches.

For a tool whose axis stands at p, the tip height is

    tip(p) = max over |u| <= R of  Z(p + u) - h(|u|)

(h: the cutter's profile, see cutters.py): the cutter is lowered until some
point of its lower surface meets the surface. That is a grey dilation of Z
with the structuring function -h, so nothing is ever "found by search" and
the answer cannot miss a contact that lies on the sampling lattice.

How we make it fast and exact enough
------------------------------------
* We never dilate the coarse map directly (on a 1 mm grid that errs by
  ~0.1 mm, measured): Z is read through sampling.Sampler (piecewise
  linear on triangles) at a fine offset lattice of spacing `d` (0.1 mm by
  default) *centred on each tool position*, so each toolpath point sees the
  cutter's disc sampled symmetrically around it.
* Toolpath points come in lines (p = o + i d e1). For one line we read a slab
  of Z on the lattice o + c d e1 + b d e2 (b = -m..m across, c = -m..n+m-1
  along), and then every offset (a, b) of the disc is a *slice* of that slab:
  out = max(out, slab[b][a : a + n] - h(a, b)), one vectorised operation per
  offset over all points of many lines at once.
* h is symmetric in b, so rows b and -b are folded first (max of the two
  rows), halving the work: ~1450 slice operations for a 6 mm ball at 0.1 mm.
* The discrete max under-estimates the continuous one only where the contact
  falls between lattice offsets: ~ h'' d^2 / 8, well under 0.002 mm for a
  3 mm radius at d = 0.1 mm on slopes below ~45 degrees (benches/cam.py
  measures it against OpenCAMLib).

Lines may run in any direction (e1 = (cos a, sin a)); the disc is rotation
invariant, so nothing else changes.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .cutters import Cutter
from .sampling import Sampler
from .segments import min_over_segment

DEFAULT_RESOLUTION = 0.1  # mm, spacing of the offset lattice and of toolpath points
_SLAB_BUDGET = 250_000  # slab elements per chunk: reading the map there takes ~15 arrays
# of its size (3 M elements were 370 MB of a finishing plan; 750 k, 20 MB of the daemon's)
_EDGE_POINTS = 5_000  # tool positions whose edge contacts are found at once
_READ_BLOCK = 32_768  # slab elements read from the map at once (its temporaries: ~12 arrays)
CACHE_ELEMENTS = 65_536  # float32 elements of one slice operation's arrays (256 kB: in L2)


@functools.lru_cache(maxsize=16)
def disc_offsets(cutter: Cutter, d: float):
    """Disc offsets grouped by |b|: [(b, a_values, h_values)], m (cached: read-only)."""
    M = cutter.radius / d
    m = int(np.floor(M + 1e-9))
    groups = []
    for b in range(m + 1):
        amax = int(np.floor(np.sqrt(max(M * M - b * b, 0.0)) + 1e-9))
        a = np.arange(-amax, amax + 1)
        h = cutter.profile(d * np.hypot(a, b))
        ok = np.isfinite(h)
        groups.append((b, a[ok], h[ok]))
    return groups, m


def drop_lines(
    sampler: Sampler,
    cutter: Cutter,
    origins,
    direction,
    n: int,
    d: float = DEFAULT_RESOLUTION,
    stride: int = 1,
):
    """Tip heights at o_l + i d e1 (i = 0..n-1, every `stride`-th) for each origin o_l.

    Shape (L, len(range(0, n, stride))). The offset lattice keeps spacing d
    whatever the stride, so a stride only thins the points, not the accuracy.
    """
    origins = np.atleast_2d(np.asarray(origins, float))
    e1 = np.asarray(direction, float)
    e1 = e1 / np.hypot(*e1)
    e2 = np.array([-e1[1], e1[0]])
    groups, m = disc_offsets(cutter, d)
    L = origins.shape[0]
    out = np.empty((L, len(range(0, n, stride))))
    per_line = (2 * m + 1) * (n + 2 * m)
    chunk = max(1, _SLAB_BUDGET // per_line)
    axis = _axis_aligned(e1, origins)
    if axis is not None and L > 1 and np.median(np.diff(np.sort(origins[:, 1 - axis]))) <= d * (1 + 1e-9):
        # lines a lattice step apart (a grid) read one new row each: a chunk may hold
        # as many as keep the ~1450 slice operations' arrays in cache
        chunk = max(chunk, CACHE_ELEMENTS // max(n, 1))
    c = np.arange(-m, n + m) * d
    b = np.arange(-m, m + 1) * d
    # lattice offsets relative to the line origin, shape (2m+1, n+2m)
    ox = c[None, :] * e1[0] + b[:, None] * e2[0]
    oy = c[None, :] * e1[1] + b[:, None] * e2[1]
    for s in range(0, L, chunk):
        o = origins[s : s + chunk]
        if axis is None:
            slab = _in_blocks(
                (o.shape[0],) + ox.shape,
                lambda r, o=o: sampler.z(o[r, 0, None, None] + ox[None], o[r, 1, None, None] + oy[None]),
            )
            table, index = slab.reshape(-1, slab.shape[-1]), np.arange(slab.shape[0] * slab.shape[1])
            index = index.reshape(slab.shape[:2])
        else:
            table, index = _axis_rows(sampler, o, axis, b, c)
        out[s : s + chunk] = _dilate_slab(table, index, groups, m, n, stride)
    if sampler.edges is not None:
        along = d * np.arange(0, n, stride)
        # in blocks of lines: the (patch, point) pairs of a whole plan's lines at once were
        # 50 MB of the daemon's toolpath peak (a sphere's coarse map has walls for edges)
        step = max(1, _EDGE_POINTS // max(along.size, 1))
        for s in range(0, L, step):
            o = origins[s : s + step]
            px = o[:, 0, None] + along[None, :] * e1[0]
            py = o[:, 1, None] + along[None, :] * e1[1]
            lines = (o, e1, d, n, stride) if n > 1 else None
            _edge_contacts(
                sampler.edges, cutter, px.ravel(), py.ravel(), out[s : s + step].reshape(-1), lines
            )
    return out


def _edge_contacts(segs, cutter, px, py, out, lines=None):
    """Raise `out` (in place) where the cutter meets the footprint's edge first.

    The edge is a cliff the lattice can straddle; each boundary segment is
    tested exactly (segments.py) against every tool point within reach.
    `lines` (origins, e1, d, n, stride): the points are those lines' points,
    which finds the pairs without a k-d tree.
    """
    R = cutter.radius
    a, b = segs[:, :3], segs[:, 3:]
    order, first, count, box = _patches(a, b, R / 3)
    mid = 0.5 * (box[:, 0:2] + box[:, 2:4])
    half = 0.5 * float(np.max(np.hypot(*(box[:, 2:4] - box[:, 0:2]).T)))
    if lines is None:
        gi, pj = _point_pairs(mid, px, py, R + half)
    else:
        gi, pj = _line_pairs(mid, R + half, *lines)
    gi, pj = _patch_may_raise(box, cutter, px, py, out, gi, pj)
    # every segment of a patch that may raise the point
    c = count[gi]
    si = order[np.repeat(first[gi], c) + np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)]
    pj = np.repeat(pj, c)
    si, pj = _may_raise(a, b, cutter, px, py, out, si, pj)
    if si.size == 0:
        return
    w = b[si] - a[si]
    # drop onto the edge = minus the lowest sweep of the edge with heights negated
    m = min_over_segment(cutter, px[pj] - a[si, 0], py[pj] - a[si, 1], w[:, 0], w[:, 1], -w[:, 2], -a[si, 2])
    np.maximum.at(out, pj, -m)


def _patches(a, b, size):
    """Segments grouped by the square of side `size` their midpoint falls in.

    Returns (order, first, count, box): patch g holds segments
    order[first[g] : first[g] + count[g]], and box[g] = (xmin, ymin, xmax, ymax,
    zmax) over their ends. A map sampled at 0.1 mm has 4000 boundary segments
    a tenth of a millimetre long, each within reach of ~2900 points of a whole
    map: 11.7 M pairs, most of a 1.65 s drop. Patches are paired first.
    """
    mid = 0.5 * (a[:, :2] + b[:, :2])
    cell = np.floor((mid - mid.min(axis=0)) / size).astype(np.int64)
    key = cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1]
    order = np.argsort(key, kind="stable")
    _, first, count = np.unique(key[order], return_index=True, return_counts=True)
    lo = np.minimum(a[order, :2], b[order, :2])
    hi = np.maximum(a[order, :2], b[order, :2])
    z = np.maximum(a[order, 2], b[order, 2])
    box = np.column_stack(
        [np.minimum.reduceat(lo, first), np.maximum.reduceat(hi, first), np.maximum.reduceat(z, first)]
    )
    return order, first, count, box


def _patch_may_raise(box, cutter, px, py, out, gi, pj):
    """(patch, point) pairs whose contact could stand above the lattice's tip: the patch's
    highest end less the profile at the point's distance from its box (no segment of it
    is nearer or higher)."""
    dx = np.maximum(np.maximum(box[gi, 0] - px[pj], px[pj] - box[gi, 2]), 0.0)
    dy = np.maximum(np.maximum(box[gi, 1] - py[pj], py[pj] - box[gi, 3]), 0.0)
    keep = box[gi, 4] - cutter.profile(np.maximum(np.hypot(dx, dy) - 1e-6, 0.0)) > out[pj]
    return gi[keep], pj[keep]


def _point_pairs(mid, px, py, reach):
    """(segment, point) index pairs within `reach` of the segment's midpoint, for scattered points."""
    none = (np.zeros(0, int), np.zeros(0, int))
    t_seg = cKDTree(mid)
    idx = _near(mid, px, py, reach)
    if idx.size == 0:
        return none
    pts = np.column_stack([px, py])
    dist, _ = t_seg.query(pts[idx], distance_upper_bound=reach)
    idx = idx[np.isfinite(dist)]
    if idx.size == 0:
        return none
    pairs = t_seg.sparse_distance_matrix(cKDTree(pts[idx]), reach, output_type="ndarray")
    return pairs["i"].astype(int), idx[pairs["j"]]


def _line_pairs(mid, reach, origins, e1, d, n, stride):
    """The same pairs for points on parallel lines o_l + i d e1 (every stride-th i).

    A midpoint's disc meets a line in an interval of i, so the pairs come from
    arithmetic: lines sorted by their offset across, the ones within reach of
    each midpoint found by bisection, and each interval expanded. On a whole
    map this is a tenth of the k-d tree's time.
    """
    e2 = np.array([-e1[1], e1[0]])
    K = len(range(0, n, stride))
    across_l = origins @ e2
    order = np.argsort(across_l, kind="stable")
    sorted_l = across_l[order]
    across_s = mid @ e2
    lo = np.searchsorted(sorted_l, across_s - reach, "left")
    hi = np.searchsorted(sorted_l, across_s + reach, "right")
    cnt = hi - lo
    seg = np.repeat(np.arange(mid.shape[0]), cnt)
    line = order[np.repeat(lo, cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
    gap = across_s[seg] - across_l[line]
    w = np.sqrt(np.maximum(reach * reach - gap * gap, 0.0))
    along = mid[seg] @ e1 - origins[line] @ e1
    k0 = np.ceil(np.maximum(np.ceil((along - w) / d - 1e-9), 0) / stride)
    k1 = np.floor(np.minimum(np.floor((along + w) / d + 1e-9), n - 1) / stride)
    k1 = np.minimum(k1, K - 1)
    c = np.maximum(k1 - k0 + 1, 0).astype(int)
    si = np.repeat(seg, c)
    k = np.repeat(k0.astype(int), c) + np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)
    return si, np.repeat(line, c) * K + k


def _may_raise(a, b, cutter, px, py, out, si, pj):
    """The (segment, point) pairs whose contact could stand above the lattice's tip.

    The cutter touches the segment no higher than its higher end less the
    profile at the point's distance from it (h increases with r, and every
    point of the segment is at least that far). Beside most of the edge the
    lattice already sees the part's top that close, so nine pairs in ten end
    here, before the exact test (on sample 3's whole map: 773 k -> 83 k pairs).
    """
    w = b[si, :2] - a[si, :2]
    qx, qy = px[pj] - a[si, 0], py[pj] - a[si, 1]
    W2 = np.einsum("ij,ij->i", w, w)
    t = np.clip((qx * w[:, 0] + qy * w[:, 1]) / np.where(W2 > 0, W2, 1.0), 0.0, 1.0)
    dist = np.hypot(qx - t * w[:, 0], qy - t * w[:, 1])
    # a micron of slack: the exact test takes points at the rim within rounding, and a
    # flat end's contact is its rim (lattice points exactly R from a segment's end)
    bound = np.maximum(a[si, 2], b[si, 2]) - cutter.profile(np.maximum(dist - 1e-6, 0.0))
    keep = bound > out[pj]
    return si[keep], pj[keep]


def _near(mid, px, py, reach):
    """Indices of points that may lie within `reach` of a segment midpoint.

    A bucket test before the exact k-d query: the map is binned into squares
    of side `reach`, and only points whose square or a neighbour holds a
    midpoint go on (on a whole-map drop most points are far from every edge,
    and the k-d query over a million points was a quarter of the time).
    """
    lo = np.minimum(mid.min(axis=0), [px.min(), py.min()]) - reach
    shape = (np.maximum(mid.max(axis=0), [px.max(), py.max()]) - lo) // reach + 3
    occ = np.zeros(shape.astype(int)[::-1], bool)
    mi = ((mid - lo) // reach).astype(int) + 1
    occ[mi[:, 1], mi[:, 0]] = True
    occ = ndimage.maximum_filter(occ, size=3)
    qi = ((px - lo[0]) // reach).astype(int) + 1
    qj = ((py - lo[1]) // reach).astype(int) + 1
    return np.flatnonzero(occ[qj, qi])


def drop_points(sampler: Sampler, cutter: Cutter, x, y, d: float = DEFAULT_RESOLUTION):
    """Tip heights at arbitrary points (each its own one-point line)."""
    x = np.asarray(x, float).ravel()
    y = np.asarray(y, float).ravel()
    return drop_lines(sampler, cutter, np.column_stack([x, y]), (1.0, 0.0), 1, d)[:, 0]


def drop_grid(sampler: Sampler, cutter: Cutter, x0, y0, nx, ny, d: float = DEFAULT_RESOLUTION):
    """Tip heights on the lattice x0 + i d, y0 + j d; shape (ny, nx)."""
    origins = np.column_stack([np.full(ny, float(x0)), y0 + d * np.arange(ny)])
    return drop_lines(sampler, cutter, origins, (1.0, 0.0), nx, d)


def _axis_aligned(e1, origins):
    """0 for lines along +x sharing one start x, 1 for +y sharing one start y, else None."""
    if abs(e1[1]) < 1e-12 and e1[0] > 0 and np.ptp(origins[:, 0]) < 1e-12:
        return 0
    if abs(e1[0]) < 1e-12 and e1[1] > 0 and np.ptp(origins[:, 1]) < 1e-12:
        return 1
    return None


def _axis_rows(sampler, o, axis, b, c):
    """The slab of axis-aligned lines as (rows, index): line l's row b is rows[index[l, m + b]].

    Neighbouring lines share most rows, so each is read (and later converted)
    once, not once per line that reaches it: 61 rows per line become ~1 on a
    whole map. Along +x, e2 = +y: rows are y = o_y + b, columns x = o_x + c.
    Along +y, e2 = -x: rows are x = o_x - b, columns y = o_y + c.
    """
    if axis == 0:
        rows = o[:, 1, None] + b[None, :]
        cols = o[0, 0] + c
    else:
        rows = o[:, 0, None] - b[None, :]
        cols = o[0, 1] + c
    uniq, inv = np.unique(np.round(rows, 9), return_inverse=True)
    read = (
        (lambda r: sampler.z_grid(cols, uniq[r]))
        if axis == 0
        else (lambda r: sampler.z_grid(uniq[r], cols).T)
    )
    return _in_blocks((uniq.size, cols.size), read), inv.reshape(rows.shape)


def _in_blocks(shape, read):
    """An array of `shape` filled by read(slice of its first axis), _READ_BLOCK elements at a
    time: reading the map takes ~12 temporaries of what is read (366 rows of 1060 a chunk of
    passes were 37 MB of a worker's peak); every value is the same as read at once."""
    out = np.empty(shape)
    step = max(1, _READ_BLOCK // max(int(np.prod(shape[1:])), 1))
    for r in range(0, shape[0], step):
        out[r : r + step] = read(slice(r, r + step))
    return out


def _dilate_slab(table, index, groups, m, n, stride=1):
    """The max over the disc's offsets, in float32 relative to the slab's top.

    The slab is given as rows and an index (line l's row b is
    table[index[l, m + b]]), and rows b and -b are gathered already folded.
    Single precision halves the memory traffic of the ~1450 passes (the whole
    cost: 1.37 -> 0.79 s for a 1001 x 1001 map). Heights are taken relative to
    the slab's highest value first, so a part 100 mm tall still resolves
    8e-6 mm, far below the 0.002 mm we promise.
    """
    if index.shape[0] <= 2 and stride == 1:
        return _dilate_columns(table, index, groups, m, n)
    k = len(range(0, n, stride))
    ref = float(np.max(table))
    z = (table - ref).astype(np.float32)
    res = np.full((index.shape[0], k), -np.inf, np.float32)
    tmp = np.empty_like(res)
    for b, avals, hvals in groups:
        row = z[index[:, m]] if b == 0 else np.maximum(z[index[:, m + b]], z[index[:, m - b]])
        for a, h in zip(avals.tolist(), hvals.tolist()):
            if a < 0:
                continue  # folded into +a: h is symmetric in a as well
            if a == 0:
                np.subtract(row[:, m : m + n : stride], np.float32(h), out=tmp)
            else:
                np.maximum(row[:, m + a : m + a + n : stride], row[:, m - a : m - a + n : stride], out=tmp)
                np.subtract(tmp, np.float32(h), out=tmp)
            np.maximum(res, tmp, out=res)
    return res.astype(np.float64) + ref


def _dilate_columns(table, index, groups, m, n):
    """_dilate_slab for one or two lines: for each column offset a, the max over the
    disc's rows first (one operation over the whole slab), then one slice per a.

    A single line's ~1450 slice operations are 1000 elements each, all call
    overhead; this order makes ~30 operations on the slab instead (a planner's
    candidate pass: 10.8 -> 3.0 ms). For many lines at once the slice order is
    faster: its arrays stay in cache.
    """
    ref = float(np.max(table))
    z = (table - ref).astype(np.float32)
    L, N = index.shape[0], z.shape[1]
    # rows b and -b folded: F[:, b] = max(row m + b, row m - b)
    F = np.empty((L, m + 1, N), np.float32)
    F[:, 0] = z[index[:, m]]
    np.maximum(z[index[:, m + 1 :]], z[index[:, m - 1 :: -1][:, :m]], out=F[:, 1:])
    H = _profile_table(groups, m)
    res = np.full((L, n), -np.inf, np.float32)
    for a in range(m + 1):
        live = np.flatnonzero(np.isfinite(H[a]))
        if live.size == 0:
            continue
        col = (F[:, live] - H[a, live][None, :, None]).max(axis=1)
        if a == 0:
            np.maximum(res, col[:, m : m + n], out=res)
        else:
            np.maximum(res, np.maximum(col[:, m + a : m + a + n], col[:, m - a : m - a + n]), out=res)
    return res.astype(np.float64) + ref


def _profile_table(groups, m):
    """h at offset (a, b), a, b = 0..m, in float32; inf outside the disc."""
    H = np.full((m + 1, m + 1), np.inf, np.float32)
    for b, avals, hvals in groups:
        for a, h in zip(avals.tolist(), hvals.tolist()):
            if a >= 0:
                H[a, b] = h
    return H
