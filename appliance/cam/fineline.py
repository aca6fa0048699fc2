"""Tips at points a fraction of a lattice step apart, all read on one lattice.

The pass ends off the part get up to 31 tips between their positions (rimline.py);
dropcutter.drop_lines would read each on a lattice centred on it. See fine_lattice_lines.
"""

from __future__ import annotations

import functools

import numpy as np

from .contact import polish
from .cutters import Cutter
from .dropcutter import _SLAB_BUDGET, _axis_aligned, _axis_rows, _edge_contacts
from .sampling import Sampler


def drop_fine_lines(sampler, cutter, origins, direction, n, d, sub, need):
    """contact.drop_lines at points d / sub apart (fine_lattice_lines), polished the same way,
    at the points `need` (bool, (lines, n)); nan at the others."""
    origins = np.atleast_2d(np.asarray(origins, float))
    e1 = np.asarray(direction, float)
    e1 = e1 / np.hypot(*e1)
    tip = fine_lattice_lines(sampler, cutter, origins, e1, n, d, sub, need)
    t = (d / sub) * np.arange(n)
    x = np.broadcast_to(origins[:, :1] + t[None, :] * e1[0], tip.shape)
    y = np.broadcast_to(origins[:, 1:2] + t[None, :] * e1[1], tip.shape)
    out = np.full(tip.shape, np.nan)
    out[need] = polish(sampler, cutter, x[need], y[need], tip[need], d)
    return out


def fine_lattice_lines(
    sampler: Sampler, cutter: Cutter, origins, direction, n: int, d: float, sub: int, need
):
    """Tip heights at o_l + q (d / sub) e1 (q = 0..n-1) for each origin o_l: points a sub-th of
    a lattice step apart, read on one lattice of spacing d for all of them.

    drop_lines centres a lattice on every point, so sub points per step read sub slabs, and
    on a short line (a pass end's ~30 moves) each slab is mostly its margins, a radius
    either side. Here the lattice is the line's own (columns c d along it): the point at
    (i + j / sub) d meets column i + a at the offset (a - j / sub) d, so every (a, b) of
    the disc is one slice of the slab for all sub phases at once, each less its own h.
    The values taken are Z(p + u) - h(|u|) at real offsets |u| <= R, as on a centred
    lattice (a lower bound of the tip, short of it by the same h'' d^2 / 8); the part's
    outline is met exactly as in drop_lines, at the points `need` (bool, (lines, n)) only
    (found by a k-d tree: the pass ends' few points). Not polished: see drop_fine_lines.
    """
    origins = np.atleast_2d(np.asarray(origins, float))
    e1 = np.asarray(direction, float)
    e1 = e1 / np.hypot(*e1)
    e2 = np.array([-e1[1], e1[0]])
    M = cutter.radius / d
    m = int(np.floor(M + 1e-9))
    nc = -(-n // sub)  # lattice steps holding the points
    L = origins.shape[0]
    out = np.empty((L, n))
    pairs = _phase_offsets(cutter, d, sub, m)
    c = np.arange(-m, nc + m + 1) * d
    b = np.arange(-m, m + 1) * d
    ox = c[None, :] * e1[0] + b[:, None] * e2[0]
    oy = c[None, :] * e1[1] + b[:, None] * e2[1]
    axis = _axis_aligned(e1, origins)
    # lines per chunk: the slab's rows and the phases' results within the drop's budget
    chunk = max(1, _SLAB_BUDGET // max((2 * m + 1) * c.size, nc * sub, 1))
    for s in range(0, L, chunk):
        o = origins[s : s + chunk]
        if axis is None:
            slab = sampler.z(o[:, 0, None, None] + ox[None], o[:, 1, None, None] + oy[None])
            table, index = slab.reshape(-1, c.size), np.arange(slab.shape[0] * slab.shape[1])
            index = index.reshape(slab.shape[:2])
        else:
            table, index = _axis_rows(sampler, o, axis, b, c)
        ref = float(np.max(table))
        z = (table - ref).astype(np.float32)
        res = np.full((o.shape[0], nc, sub), -np.inf, np.float32)
        tmp = np.empty_like(res)
        for bb, folded in enumerate(_folded_rows(z, index, m)):
            for a, h in pairs[bb]:
                np.subtract(folded[:, m + a : m + a + nc, None], h[None, None, :], out=tmp)
                np.maximum(res, tmp, out=res)
        out[s : s + chunk] = res.reshape(o.shape[0], nc * sub)[:, :n].astype(np.float64) + ref
    if sampler.edges is not None:
        line, q = np.nonzero(need)
        t = (d / sub) * q
        px, py = origins[line, 0] + t * e1[0], origins[line, 1] + t * e1[1]
        z = out[line, q]
        _edge_contacts(sampler.edges, cutter, px, py, z)
        out[line, q] = z
    return out


def _folded_rows(z, index, m):
    """Rows b and -b of every line's slab (line l's row b is z[index[l, m + b]]), max'ed: b = 0..m."""
    yield z[index[:, m]]
    for b in range(1, m + 1):
        yield np.maximum(z[index[:, m + b]], z[index[:, m - b]])


@functools.lru_cache(maxsize=16)
def _phase_offsets(cutter: Cutter, d: float, sub: int, m: int):
    """Per |b|: [(a, h of every phase j at offset ((a - j / sub) d, b d), float32, inf beyond R)]."""
    R = cutter.radius
    j = np.arange(sub) / sub
    groups = []
    for b in range(m + 1):
        row = []
        for a in range(-m, m + 2):
            r = d * np.hypot(a - j, b)
            if np.all(r > R * (1 + 1e-12)):
                continue
            h = np.where(r <= R * (1 + 1e-12), cutter.profile(np.minimum(r, R)), np.inf)
            row.append((a, h.astype(np.float32)))
        groups.append(row)
    return groups
