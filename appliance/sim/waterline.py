"""Where the ink meets the part: the waterline (or contact line) as a signed distance.

Through a pixel's liquid-plane point P0 the part covers a fraction
a = clip(0.5 + sdf / (2 pix), 0, 1), sdf = Surface.level_sdf(P0, L) in mm and
pix the pixel's size on the plane. The ramp is two pixels wide so that BOTH
pixels straddling the waterline lie on it: a row's 50 % crossing, found by
linear interpolation between them, is then exactly where sdf = 0. The sdf is
exact (analytic) in a band a few pixels wide around the waterline; elsewhere a
grid approximation decides inside/outside. With a meniscus the ink climbs the
part: the contact line sits h above the free surface (physics.meniscus_rise),
and is seen in perspective from that height.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import physics
from .partgrid import curvature_grid, lookup


def contact_curvature(surface, grid, x, y, tier):
    """Curvature of the contact line through plane points x, y on each one's tier's top."""
    kg = curvature_grid(surface)
    gx, gy = grid.coords(x, y)
    out = np.zeros(x.size, np.float32)
    for ti, k in enumerate(kg):
        sel = tier == ti
        if sel.any():
            out[sel] = lookup(k, gx[sel], gy[sel], (0.0, 0.0, 0.0, 0.0))[:, 0]
    return out


def exact_level_sdf(surface, grid, x, y, level, eps=1e-4):
    """Surface.level_sdf, term for term, but evaluating a tier's top only where it
    can decide the result: where the grid says the top's distance is more than
    0.5 mm beyond the footprint's, min(footprint, top) is the footprint (exact
    and cheap). Tops like sample 3's (a Newton inversion per call) cost 10x
    more than a footprint."""
    x = x.astype(np.float64)
    y = y.astype(np.float64)
    level = np.broadcast_to(np.asarray(level, np.float64), x.shape)
    best = np.full(x.shape, -np.inf)
    gx, gy = grid.coords(x, y)
    for t, tg in zip(surface.tiers, grid.tiers):
        F = np.asarray(t.footprint(x, y), float)
        ft = lookup(tg.FT, gx, gy, (-grid.margin, 0.0, 0.0, 0.0))
        d = lookup(tg.N, gx, gy)
        g = np.hypot(d[:, 0], d[:, 1]).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            d_approx = np.where(g > 1e-6, (ft[:, 1] - level) / g, np.inf)
        need = ~(d_approx > F + 0.5)
        val = F.copy()
        if need.any():
            xs, ys, lv = x[need], y[need], level[need]
            z = np.broadcast_to(np.asarray(t.top(xs, ys), float), xs.shape)
            zx = (t.top(xs + eps, ys) - t.top(xs - eps, ys)) / (2 * eps)
            zy = (t.top(xs, ys + eps) - t.top(xs, ys - eps)) / (2 * eps)
            gg = np.hypot(zx, zy)
            with np.errstate(divide="ignore", invalid="ignore"):
                d_top = np.where(gg > 1e-9, (z - lv) / gg, np.where(z >= lv, np.inf, -np.inf))
            val[need] = np.minimum(F[need], d_top)
        best = np.maximum(best, val)
    return best


def approx_level_sdf(grid, x, y, level):
    """Grid approximation of level_sdf and of which tier/kind of edge wins."""
    best = np.full(x.size, -np.inf, np.float32)
    tier = np.zeros(x.size, np.int16)
    wall = np.zeros(x.size, bool)
    slope = np.zeros(x.size, np.float32)
    fgx = np.zeros(x.size, np.float32)
    fgy = np.zeros(x.size, np.float32)
    gx, gy = grid.coords(x, y)
    for ti, tg in enumerate(grid.tiers):
        v, w, g, fx, fy = _tier_level_sdf(grid, tg, gx, gy, level)
        better = v > best
        best[better] = v[better]
        tier[better] = ti
        wall[better] = w[better]
        slope[better] = g[better]
        fgx[better] = fx[better]
        fgy[better] = fy[better]
    return best, tier, wall, slope, fgx, fgy


def _tier_level_sdf(grid, tg, gx, gy, level):
    """One tier's share of approx_level_sdf: its distance, whether its wall (not its top)
    is the edge, its top's slope and its footprint's gradient."""
    ft = lookup(tg.FT, gx, gy, (-grid.margin, 0.0, 0.0, 0.0))
    d = lookup(tg.N, gx, gy)
    g = np.hypot(d[:, 0], d[:, 1])
    F, T = ft[:, 0], ft[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        dtop = np.where(g > 1e-6, (T - level) / g, np.where(T >= level, 1e3, -1e3)).astype(np.float32)
    return np.minimum(F, dtop), F < dtop, g, d[:, 2], d[:, 3]


def top_height(grid, x, y, tier):
    """Height of each point's tier's top (continued past its footprint on the grid)."""
    gx, gy = grid.coords(x, y)
    out = np.zeros(x.size, np.float32)
    for ti, tg in enumerate(grid.tiers):
        sel = tier == ti
        if sel.any():
            out[sel] = lookup(tg.FT, gx[sel], gy[sel], (-grid.margin, 0.0, 0.0, 0.0))[:, 1]
    return out


@dataclass
class Waterline:
    """The waterline layer of a block of pixels (flat arrays, one entry per pixel)."""

    alpha: np.ndarray  # coverage of the part at the waterline, the 2 px ramp
    level: np.ndarray  # height of the contact line (the free surface's, plus the meniscus)
    tier: np.ndarray  # which tier's edge wins there
    wall: np.ndarray  # the edge is a wall (side of a tier), not a top
    fgx: np.ndarray  # the footprint's gradient there (which way the wall faces)
    fgy: np.ndarray
    band: np.ndarray  # within a few pixels of the waterline: the sdf there is exact


def waterline_layer(surface, grid, effects, x0, y0, kx, ky, pix, lvl) -> Waterline:
    """The waterline, or with a meniscus the contact line, through the pixels' rays
    (liquid-plane points x0, y0, travel kx, ky, pixel size pix), the free surface at lvl."""
    approx, wtier, wwall, wslope, fgx, fgy = approx_level_sdf(grid, x0, y0, lvl)
    xc, yc, lc = x0, y0, lvl
    if effects.meniscus:
        xc, yc, lc = _contact_line(surface, grid, effects, x0, y0, kx, ky, lvl, wslope)
        approx, wtier, wwall, wslope, fgx, fgy = approx_level_sdf(grid, xc, yc, lc)
    band = np.abs(approx) < 4 * pix + 0.02
    sdf = approx.copy()
    if band.any():
        sdf[band] = exact_level_sdf(surface, grid, xc[band], yc[band], lc[band])
    a_wl = np.clip(0.5 + sdf / (2 * pix), 0.0, 1.0).astype(np.float32)
    return Waterline(a_wl, lc, wtier, wwall, fgx, fgy, band)


def _contact_line(surface, grid, effects, x0, y0, kx, ky, lvl, wslope):
    """Where the pixels' rays see the contact line: plane points xc, yc and its height lc.

    The contact line on the top sits h(beta) above the free surface, beta the top's
    slope where the contact line is (found by iterating from the slope at the free
    surface's own level curve, wslope). A wall does not drag the ink over the top: at a
    sharp edge the contact line pins, so the top near a wall comes out with its own
    slope's rise, and on the wall itself the ink climbs h(90 deg) - which only moves
    where a wall facing the camera shows its waterline.
    With the second model the rise also depends on the contact line's own curvature
    there (the top's level curve through the contact point).

    On a part of several tiers each tier has its own contact line: the ink that climbs
    one tier's wall does not stand on a lower tier's face twenty millimetres away, and a
    face flatter than the contact angle sheds its ink however high a wall beside it is.
    A pixel sees the tier that is furthest out of the ink at its own contact line."""
    if len(grid.tiers) == 1:
        return _tier_contact_line(surface, grid, effects, 0, x0, y0, kx, ky, lvl, wslope)
    best = None
    for ti in range(len(grid.tiers)):
        slope = _one_tier(grid, ti, x0, y0, lvl)[2]
        xc, yc, lc = _tier_contact_line(surface, grid, effects, ti, x0, y0, kx, ky, lvl, slope)
        v = _one_tier(grid, ti, xc, yc, lc)[0]
        if best is None:
            best = [v, xc, yc, lc]
            continue
        better = v > best[0]
        best = [np.where(better, a, b) for a, b in zip((v, xc, yc, lc), best)]
    return best[1], best[2], best[3]


def _one_tier(grid, ti, x, y, level):
    """_tier_level_sdf of tier ti at plane points x, y."""
    gx, gy = grid.coords(x, y)
    return _tier_level_sdf(grid, grid.tiers[ti], gx, gy, level)


def _tier_contact_line(surface, grid, effects, ti, x0, y0, kx, ky, lvl, wslope):
    """_contact_line on tier ti alone."""
    theta = math.radians(effects.contact_angle_deg)
    l_c = effects.capillary_length_mm
    tier = np.full(x0.size, ti, np.int16)

    def rise(b, x=None, y=None):
        if x is None or not effects.contact_line_curvature:
            return physics.meniscus_rise(b, l_c, theta).astype(np.float32)
        kappa = contact_curvature(surface, grid, x, y, tier)
        return physics.meniscus_rise_curved(b, kappa, l_c, theta).astype(np.float32)

    h = rise(np.arctan(wslope), x0, y0)
    for _ in range(2):
        lc = lvl + h
        xs, ys = x0 + kx * h, y0 + ky * h
        _, wwall, wslope, _, _ = _one_tier(grid, ti, xs, ys, lc)
        h = rise(np.arctan(wslope), xs, ys)
    lc = lvl + h
    # on a wall the ink climbs h(90 deg), but never past the wall's top edge
    seen_h = h.copy()
    if wwall.any():
        rim = top_height(grid, x0[wwall], y0[wwall], tier[wwall]) - lvl[wwall]
        seen_h[wwall] = np.clip(rim, 0.0, rise(np.pi / 2))
    # the contact line is seen_h above the free surface: seen in perspective from there
    return x0 + kx * seen_h, y0 + ky * seen_h, lc
