"""Polishing drop-cutter tips on steep faces.

The drop-cutter (dropcutter.py) takes the max of Z(p + u) - h(|u|) over a
lattice of offsets u of spacing d. Where the contact falls between lattice
offsets it under-estimates the tip by about h''(rho) d^2 / 8, and on a steep
face h'' grows like 1 / (R cos^3 alpha): for a 1 mm ball at d = 0.02 mm on an
80 degree face that is 0.02-0.03 mm, a gouge (sample 4). Refining the whole
lattice would cost (R/d)^2 more; instead, at the points where the surface
under the cutter is steep, we look for the contact near where a plane of
the local slope would touch the cutter and search a few shrinking 5 x 5
patterns of offsets around it (d, d/4, d/16 apart).

A flat end is worse everywhere, not only on steep faces: on any slope it
touches with the very edge of its bottom (h jumps from 0 to infinity at R),
and the lattice disc's outermost offsets in the uphill direction stop short
of the rim by up to a lattice step: low by slope x that shortfall (0.007 mm
on a 0.25 slope with a 6 mm flat end at d = 0.1). So for a flat end every
point's rim is searched: Z at 64 points around the circle of radius R, then
three shrinking fans of 9 angles around the best.

On a coarse map (the daemon's 50-cell grid: 1.2 mm cells under a 6 mm ball) a whole
cutter's disc is a few dozen cells, and a tip beside a wall is met exactly against every
triangle under the cutter, with no search first (DISC_CELLS): the ring scans were most
of the daemon's toolpath.

Every value tried is Z(p + u) - h(|u|) for a real offset |u| <= R, so it is a
lower bound of the true tip: taking the max with the lattice answer can only
move the tip towards the true one, never above it (no scallop added).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .cutters import Cutter
from .dropcutter import DEFAULT_RESOLUTION
from .dropcutter import drop_lines as lattice_lines
from .sampling import Sampler
from .segments import min_over_segment

WINDOW = 2  # cells either side of the found contact whose triangles are met exactly
STEEP = 0.8  # |grad Z| above which a tip is polished (~39 degrees)
# |grad Z| of a wall (55 degrees): an axis with one within reach is polished wherever it
# stands, and its contact met exactly (may_have_steep_faces is a bound from the larger x and
# y slopes, so a gentler one would take in a whole dome whose tips the lattice has right)
WALL = 1.43
# cells in the window of a whole cutter's disc up to which polish meets every cell under the
# cutter exactly instead of searching for the contact first (7 x 7 for the daemon's map)
DISC_CELLS = 81
_K = np.arange(-2, 3)
_PU, _PV = [a.ravel() for a in np.meshgrid(_K, _K)]


def _F(sampler, cutter, x, y, ux, uy):
    R = cutter.radius
    r = np.hypot(ux, uy)
    ok = r <= R
    val = sampler.z(x + ux, y + uy) - cutter.profile(np.minimum(r, R))
    return np.where(ok, val, -np.inf)


def surface_gradient(sampler, x, y, e):
    gx = (sampler.z(x + e, y) - sampler.z(x - e, y)) / (2 * e)
    gy = (sampler.z(x, y + e) - sampler.z(x, y - e)) / (2 * e)
    return gx, gy


def plane_contact(cutter, gx, gy):
    """Contact offset of the cutter on a plane of gradient (gx, gy)."""
    G = np.hypot(gx, gy)
    rc = cutter.corner_radius
    a = cutter.radius - rc
    rad = a + rc * G / np.sqrt(1 + G * G)
    Gs = np.where(G > 0, G, 1.0)
    rad = np.where(G > 0, np.minimum(rad, cutter.radius * (1 - 1e-9)), 0.0)
    return gx / Gs * rad, gy / Gs * rad


_RIM = 64
_FAN = np.arange(-4, 5)


def polish_rim(sampler: Sampler, cutter: Cutter, x, y, tip, chunk=20_000):
    """Tips of a flat end raised to the highest surface point under its rim circle."""
    out = np.array(tip, float, copy=True)
    shape = out.shape
    x, y, out = np.ravel(x), np.ravel(y), out.reshape(-1)
    R = cutter.radius
    ang = 2 * np.pi * np.arange(_RIM) / _RIM
    for s in range(0, x.size, chunk):
        px, py = x[s : s + chunk, None], y[s : s + chunk, None]
        f = sampler.z(px + R * np.cos(ang), py + R * np.sin(ang))
        j = np.argmax(f, axis=1)
        r = np.arange(f.shape[0])
        best, th = f[r, j], ang[j]
        step = 2 * np.pi / _RIM / 4
        for _ in range(3):
            a = th[:, None] + step * _FAN[None, :]
            f = sampler.z(px + R * np.cos(a), py + R * np.sin(a))
            j = np.argmax(f, axis=1)
            best = np.maximum(best, f[r, j])
            th = a[r, j]
            step /= 4
        out[s : s + chunk] = np.maximum(out[s : s + chunk], best)
    return out.reshape(shape)


def polish(sampler: Sampler, cutter: Cutter, x, y, tip, d, chunk=2_000, off_part=True):
    """Tips `tip` at (x, y) from the lattice drop-cutter, raised to nearer the exact contact where steep.

    off_part: polish positions off the part too (a program's: see below). The opening's
    lattice leaves them: the band a radius wide around a 100 mm part's outline is a
    tenth of its lattice, every node a ring scan, for a reach mask that errs only
    towards measuring more."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if cutter.kind == "flat":
        tip = polish_rim(sampler, cutter, x, y, tip)
    out = np.array(tip, float, copy=True)
    shape = out.shape
    x, y, out = x.ravel(), y.ravel(), out.reshape(-1)
    e = d / 2
    # only points near something steep (the contact is within R of the axis)
    near = np.flatnonzero(sampler.may_be_steep(x, y, cutter.radius + e, STEEP) & np.isfinite(out))
    x, y = x[near], y[near]
    gx, gy = surface_gradient(sampler, x, y, e)
    ux, uy = plane_contact(cutter, gx, gy)
    gx2, gy2 = surface_gradient(sampler, x + ux, y + uy, e)
    # an axis on a flat beside a wall (a floor at a wall's foot, or the base off the part
    # where a pass runs off the outline to finish the rim) reads no slope at the axis nor at
    # the plane's contact, yet the cutter meets the wall with its side: 0.085 mm low beside
    # an 84-degree wall (benches/steep.py), 0.008 mm on a 79-degree face beside the outline
    steep = (np.hypot(gx, gy) > STEEP) | (np.hypot(gx2, gy2) > STEEP)
    faces = sampler.may_have_steep_faces(x, y, cutter.radius + e, WALL)
    on = sampler.on_part(x, y)
    steep |= faces & on
    if off_part:
        steep |= ~on & sampler.may_have_steep_faces(x, y, cutter.radius + e, STEEP)
    span = int(np.ceil(cutter.radius / min(sampler.dx, sampler.dy)))
    if (2 * span + 1) ** 2 <= DISC_CELLS:
        # a coarse map (the daemon's: 1.2 mm cells under a 6 mm ball): every cell under the
        # cutter is met exactly, which is the tip itself, with no search to centre a window
        w = np.flatnonzero(steep & faces)
        for s in range(0, w.size, chunk):
            k = w[s : s + chunk]
            exact = facet_contacts(sampler, cutter, x[k], y[k], x[k], y[k], span, floor=out[near[k]])
            out[near[k]] = np.maximum(out[near[k]], exact)
        steep &= ~faces
    sel = np.flatnonzero(steep)
    x, y, gx2, gy2, idx, faces = x[sel], y[sel], gx2[sel], gy2[sel], near[sel], faces[sel]
    half = chunk // 2
    for s in range(0, idx.size, half):
        k0 = np.arange(s, min(s + half, idx.size))
        # two starts per point: where a plane of the local slope would touch,
        # and the best of a scan of rings near the rim (beside a cliff or a
        # crease the plane's guess can be far from the contact: 0.02 mm low
        # on sample 4's top edge)
        gcx, gcy = plane_contact(cutter, gx2[k0], gy2[k0])
        rcx, rcy = _ring_scan(sampler, cutter, x[k0], y[k0])
        k = np.concatenate([k0, k0])
        px, py = x[k], y[k]
        cx, cy = np.concatenate([gcx, rcx]), np.concatenate([gcy, rcy])
        best = np.full(k.size, -np.inf)
        f0 = _F(sampler, cutter, px, py, cx, cy)
        best = np.maximum(best, f0)
        sp = d
        for _ in range(3):
            ox = cx[:, None] + sp * _PU[None, :]
            oy = cy[:, None] + sp * _PV[None, :]
            f = _F(sampler, cutter, px[:, None], py[:, None], ox, oy)
            j = np.argmax(f, axis=1)
            r = np.arange(k.size)
            fb = f[r, j]
            cx, cy = ox[r, j], oy[r, j]
            best = np.maximum(best, fb)
            sp /= 4
        n = k0.size
        out[idx[k0]] = np.maximum(out[idx[k0]], np.maximum(best[:n], best[n:]))
        # steep faces within reach: meet their triangles exactly (the part's outline is met
        # exactly already, as edges, by the lattice drop)
        w = np.flatnonzero(faces[k0])
        if w.size:
            second = best[n + w] > best[w]
            won, lost = np.where(second, n + w, w), np.where(second, w, n + w)
            _meet_faces(sampler, cutter, x, y, k0[w], cx, cy, won, lost, out, idx)
    return out.reshape(shape)


def _meet_faces(sampler, cutter, x, y, k1, cx, cy, won, lost, out, idx):
    """Meet the triangles round the contacts cx[won], cy[won] exactly, for the points k1, and
    round cx[lost], cy[lost] too where the losing start ended more than a window away.

    Round the better start's contact only is not enough on a crease: a cutter on a floor
    that touches the wall with its side has the floor's contact win the search by a hair,
    and the wall's triangles lie beyond the window (0.009 mm low beside benches/steep.py's
    85-degree side)."""
    far = (np.abs(cx[won] - cx[lost]) > WINDOW * sampler.dx) | (
        np.abs(cy[won] - cy[lost]) > WINDOW * sampler.dy
    )
    for k, c in ((k1, won), (k1[far], lost[far])):
        if k.size:
            exact = facet_contacts(sampler, cutter, x[k], y[k], x[k] + cx[c], y[k] + cy[c], floor=out[idx[k]])
            out[idx[k]] = np.maximum(out[idx[k]], exact)


def facet_contacts(sampler: Sampler, cutter: Cutter, px, py, gx, gy, cells: int = WINDOW, floor=None):
    """Exact tip heights at (px, py) against the triangles of the cells within `cells` of the
    cell holding (gx, gy), the contact found so far.

    The surface is those triangles, so a cutter touches one of them inside (a plane's
    contact, plane_contact), or one of their sides or corners (segments.py, exact). The
    lattice and the pattern search only sample offsets: on an 85-degree face h'' is
    1 / (R cos^3) ~ 500 /mm for a 6 mm ball, and an offset 0.015 mm from the contact reads
    0.06 mm low (benches/steep.py's gouge). -inf where nothing of the window is under the cutter.

    `floor` (per point, optional): the tip already known; a cell whose highest corner less
    h at its nearest point to the axis cannot rise above it is not met (it could not change
    max(floor, result)). Of a window's 25 cells one to four pass on a sphere's wall; every
    (cell, point) pair left is met in one call per side, not one per cell.

    The window is taken as its rows and its columns apart first: a row whose highest cell,
    less h at the row's own distance from the axis, cannot rise above `floor` has no cell
    that can (and so for a column), so only the cells of the rows and columns left are
    looked at one by one (the whole window's were a third of the daemon's polish).
    """
    px, py = np.ravel(np.asarray(px, float)), np.ravel(np.asarray(py, float))
    best = np.full(px.shape, -np.inf)
    dx, dy, R = sampler.dx, sampler.dy, cutter.radius
    off = np.arange(-cells, cells + 1)[:, None]
    ic = np.floor((np.ravel(gx) - sampler.x0) / dx).astype(np.intp)
    jc = np.floor((np.ravel(gy) - sampler.y0) / dy).astype(np.intp)
    cols = np.clip(ic[None, :] + off, 0, sampler.nx - 2)  # (window, points)
    rows = np.clip(jc[None, :] + off, 0, sampler.ny - 2)
    # each column's and each row's distance from the axis
    ex = np.maximum(np.maximum(sampler.x0 + dx * cols - px, px - sampler.x0 - dx * (cols + 1)), 0.0)
    ey = np.maximum(np.maximum(sampler.y0 + dy * rows - py, py - sampler.y0 - dy * (rows + 1)), 0.0)
    reach = R * (1 + 1e-9) + 1e-12
    row_ok, col_ok = ey <= reach, ex <= reach
    if floor is not None:
        along_x, along_y = _window_tops(sampler, cells)
        f = np.ravel(floor)[None, :]
        icc, jcc = np.clip(ic, 0, sampler.nx - 2), np.clip(jc, 0, sampler.ny - 2)
        row_ok &= along_x[rows, icc[None, :]] - cutter.profile(np.minimum(ey, R)) > f
        col_ok &= along_y[jcc[None, :], cols] - cutter.profile(np.minimum(ex, R)) > f
    r, c, p = np.nonzero(row_ok[:, None, :] & col_ok[None, :, :])
    near = np.hypot(ey[r, p], ex[c, p])
    i, j = cols[c, p], rows[r, p]
    cell = j * (sampler.nx - 1) + i
    live = near <= reach
    if floor is not None:
        live &= sampler.cell_top.ravel()[cell] - cutter.profile(np.minimum(near, R)) > np.ravel(floor)[p]
    keep = np.flatnonzero(live)
    p, i, j, cell = p[keep], i[keep], j[keep], cell[keep]
    if p.size == 0:
        return best.reshape(np.shape(gx))
    qx, qy = px[p] - (sampler.x0 + dx * i), py[p] - (sampler.y0 + dy * j)  # from the cell's origin
    val = _plane_contacts(sampler, cutter, cell, qx, qy)
    # each cell meets its bottom and left sides and its diagonal. Its top and right sides are
    # the bottom and left of the cells above and beside it, met there when that cell is
    # live; when it is not, its bound holds for its sides as well, and they cannot rise above
    # `floor`. Only the window's last row and column have no cell beyond them to meet theirs.
    zc = dict(zip(((0, 0), (1, 0), (0, 1), (1, 1)), (g.ravel()[cell] for g in sampler.corner_grids)))
    for (a, b), only in (
        (((0, 0), (1, 0)), None),
        (((0, 0), (0, 1)), None),
        (((0, 0), (1, 1)), None),
        (((0, 1), (1, 1)), j == rows[-1][p]),
        (((1, 0), (1, 1)), i == cols[-1][p]),
    ):
        k = slice(None) if only is None else np.flatnonzero(only)
        za = zc[a][k]
        m = min_over_segment(
            cutter,
            qx[k] - a[0] * dx,
            qy[k] - a[1] * dy,
            (b[0] - a[0]) * dx,
            (b[1] - a[1]) * dy,
            za - zc[b][k],
            -za,
        )
        val[k] = np.maximum(val[k], -m)
    np.maximum.at(best, p, val)
    return best.reshape(np.shape(gx))


def _plane_contacts(sampler, cutter, cell, qx, qy):
    """Tips of a cutter at (qx, qy) from each cell's origin touching the inside of the cell's
    triangles (-inf where the touch falls outside both). Where a plane touches the cutter
    depends on the plane's slope alone: it is found once per cell of the call."""
    cells, back = np.unique(cell, return_inverse=True)
    g00, g10, g01, g11 = (g.ravel()[cells] for g in sampler.corner_grids)
    dx, dy = sampler.dx, sampler.dy
    val = np.full(cell.size, -np.inf)
    for upper, sx, sy in (
        (True, (g10 - g00) / dx, (g11 - g10) / dy),
        (False, (g11 - g01) / dx, (g01 - g00) / dy),
    ):
        ux, uy = plane_contact(cutter, sx, sy)
        at0 = g00 + sx * ux + sy * uy - cutter.profile(np.hypot(ux, uy))  # the tip over the origin
        ux, uy, sx, sy, at0 = ux[back], uy[back], sx[back], sy[back], at0[back]
        u, v = (qx + ux) / dx, (qy + uy) / dy
        inside = (np.minimum(u, v) >= 0) & (np.maximum(u, v) <= 1) & ((u >= v) if upper else (u <= v))
        np.maximum(val, np.where(inside, at0 + sx * qx + sy * qy, -np.inf), out=val)
    return val


def _window_tops(sampler, cells):
    """Each cell's highest neighbour top within `cells` columns (along x) and within `cells`
    rows (along y), kept on the sampler: a bound for a whole row or column of a window."""
    cache = sampler.__dict__.setdefault("_window_tops", {})
    if cells not in cache:
        cache[cells] = tuple(
            ndimage.maximum_filter1d(sampler.cell_top, 2 * cells + 1, axis=a, mode="nearest") for a in (1, 0)
        )
    return cache[cells]


_RING_R = np.array([0.6, 0.75, 0.85, 0.92, 0.97, 0.995])
_RING_A = 2 * np.pi * np.arange(48) / 48


def _ring_scan(sampler, cutter, px, py):
    """Offset of the best of 6 x 48 points on rings out to the rim, per point."""
    r = cutter.radius * _RING_R[:, None]
    ux = (r * np.cos(_RING_A)[None, :]).ravel()
    uy = (r * np.sin(_RING_A)[None, :]).ravel()
    f = _F(sampler, cutter, px[:, None], py[:, None], ux[None, :], uy[None, :])
    j = np.argmax(f, axis=1)
    return ux[j], uy[j]


def drop_lines(sampler, cutter, origins, direction, n, d=DEFAULT_RESOLUTION):
    """The lattice drop-cutter, polished on steep faces so a tip is never low by the
    lattice's h'' d^2 / 8 there: a low tip is a gouge. Every finishing tip comes from here."""
    origins = np.atleast_2d(np.asarray(origins, float))
    e1 = np.asarray(direction, float)
    e1 = e1 / np.hypot(*e1)
    tip = lattice_lines(sampler, cutter, origins, e1, n, d)
    t = d * np.arange(n)
    x = origins[:, :1] + t[None, :] * e1[0]
    y = origins[:, 1:2] + t[None, :] * e1[1]
    return polish(sampler, cutter, x, y, tip, d)


def drop_points(sampler, cutter, x, y, d=DEFAULT_RESOLUTION):
    """drop_lines at scattered points (each a line of one position)."""
    x = np.asarray(x, float).ravel()
    y = np.asarray(y, float).ravel()
    return drop_lines(sampler, cutter, np.column_stack([x, y]), (1.0, 0.0), 1, d)[:, 0]
