"""Render one camera frame of the virtual bench: the compositor.

What the camera sees through each pixel: its ray leaves the camera centre C,
passes the liquid plane at P0 and, on the way, may meet the part where it
stands above the ink. The ink is opaque, so anything below the liquid is never
seen. Three layers, each worked out in a module of its own and put together
here:

1. The waterline (waterline.py): the part's coverage of a pixel is a 2 px
   ramp of the signed distance to the level curve (or, with a meniscus, to the
   contact line), so a row's 50 % crossing is exactly the curve.
2. The part above the liquid, in perspective (trace.py: a sphere tracer on the
   part's cached grids, partgrid.py). A ray that meets the part well away from
   P0 is occluded by it: the part hides the waterline there (walls and rims
   that face away from the optical axis). Where a rim hides what lies behind
   it, _silhouette gives its edge the same analytic 2 px ramp.
3. Lambertian shading of the part (normal from the grids) over the flat ink
   with glare and dust on it, then the camera: lamp flicker, vignetting, blur,
   noise, salt and pepper, JPEG (effects.py). Lens distortion is in the
   per-pixel map (each pixel of the distorted image is traced along its true
   ray); stage wobble shifts that map by a fraction of a pixel.

Everything random is drawn from the `rng` passed in, so a frame is a pure
function of (surface, level, rig, effects, rng state).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from . import physics
from . import surfaces as _surfaces
from .effects import PRESETS, Effects, camera_effects, effects_preset, liquid_layer, wobbled
from .partgrid import curvature_grid, lookup, surface_grid
from .pockets import held_level, under_pool
from .rig import PixelMap, Rig, pixel_map
from .trace import trace, trace_image
from .waterline import waterline_layer

# What tests and benches import from here besides the frame itself (each lives in its own module:
# effects.py, partgrid.py, trace.py).
__all__ = [
    "PRESETS",
    "Effects",
    "curvature_grid",
    "effects_preset",
    "liquid_level",
    "part_layer",
    "part_layer_roi",
    "render_frame",
    "surface_grid",
    "trace",
]


# -- shading -----------------------------------------------------------------------


def _shade(grid, rig, x, y, tier, wall):
    """Lambertian brightness (0..1) of the part at plane points x, y."""
    out = np.zeros(x.size, np.float32)
    light = rig.light_unit().astype(np.float32)
    for ti, tg in enumerate(grid.tiers):
        m = tier == ti
        if not m.any():
            continue
        gx, gy = grid.coords(x[m], y[m])
        d = lookup(tg.N, gx, gy)
        w = wall[m]
        # top: n ~ (-dz/dx, -dz/dy, 1); wall: outward horizontal normal = -grad sdf
        nx = np.where(w, -d[:, 2], -d[:, 0])
        ny = np.where(w, -d[:, 3], -d[:, 1])
        nz = np.where(w, 0.0, 1.0).astype(np.float32)
        norm = np.sqrt(nx * nx + ny * ny + nz * nz) + 1e-12
        lam = (nx * light[0] + ny * light[1] + nz * light[2]) / norm
        out[m] = rig.ambient + rig.diffuse * np.maximum(lam, 0)
    return out


def _silhouette(surface, grid, rig, level, x0, y0, kx, ky, pix, a_wl, wtier, wwall, hidden_tier, behind=None):
    """Analytic coverage of pixels next to a silhouette (a rim hiding what is behind).

    For each tier, find where the pixel's ray crosses the tier's top (Newton on
    top(P(z)) = z, exact top function) and take the footprint's signed distance
    there: the rim's silhouette is where it is zero, and, like the waterline, the
    coverage is a 2 px linear ramp of it (pixel size scaled to that height). The
    tiers are composited front to back over the waterline layer.
    """
    n = x0.size
    x0d, y0d = x0.astype(np.float64), y0.astype(np.float64)
    kxd, kyd = kx.astype(np.float64), ky.astype(np.float64)
    k = np.hypot(kxd, kyd)
    Hc = rig.height_mm
    cover, zs, shades = [], [], []
    for ti, t in enumerate(surface.tiers):
        tg = grid.tiers[ti]
        # The top from the grid (bilinear, ~1e-4 mm; an error dz moves the point
        # seen by only dz * k <= dz / 4), the footprint's distance exact (cheap).
        gx, gy = grid.coords(x0d, y0d)
        z = lookup(tg.FT, gx, gy)[:, 1].astype(np.float64)
        for _ in range(6):
            px, py = x0d + kxd * (z - level), y0d + kyd * (z - level)
            gx, gy = grid.coords(px, py)
            T = lookup(tg.FT, gx, gy)[:, 1]
            d = lookup(tg.N, gx, gy)
            dg = d[:, 0] * kxd + d[:, 1] * kyd - 1.0
            dg = np.where(np.abs(dg) < 0.05, -0.05, dg)  # grazing: damp the step
            z = z - np.clip((T - z) / dg, -5.0, 5.0)
        z = _met_or_sought(grid, tg, x0d, y0d, kxd, kyd, level, z)
        px, py = x0d + kxd * (z - level), y0d + kyd * (z - level)
        F = np.asarray(t.footprint(px, py), float)
        pz = pix * (Hc - (z - level)) / Hc
        c = np.clip(0.5 + F / (2 * pz), 0.0, 1.0)
        # The tier's top covers the pixel wherever the ray meets it above the
        # liquid - except on the ramp of a waterline that runs on this tier's
        # smooth top: there the ray meets the top just above the liquid and the
        # waterline layer draws the edge. A rim that stands clear of its own
        # waterline, or whose waterline runs on a wall facing away (hidden; the
        # rim's edge then meets the waterline continuously as the rim sinks to
        # the liquid), always covers.
        top_ramp = (wtier == ti) & ~wwall & (a_wl < 1.0)
        clear = ~top_ramp | ((z - level) * k > 2 * pix) | (hidden_tier == ti)
        c = np.where(clear & (z > level), c, 0.0)
        cover.append(c)
        zs.append(z)
        sh = np.zeros(n, np.float32)
        m = c > 0
        if m.any():
            sh[m] = _shade(
                grid,
                rig,
                px[m].astype(np.float32),
                py[m].astype(np.float32),
                np.full(int(m.sum()), ti, np.int16),
                np.zeros(int(m.sum()), bool),
            )
        shades.append(sh)
    cover, zs, shades = np.array(cover), np.array(zs), np.array(shades)
    order = np.argsort(-zs, axis=0)
    remaining = np.ones(n)
    colour = np.zeros(n)
    cols = np.arange(n)
    for rank in range(len(surface.tiers)):
        ti = order[rank]
        take = remaining * cover[ti, cols]
        colour += take * shades[ti, cols]
        remaining -= take
    s_wl = _shade(grid, rig, x0, y0, wtier, wwall)
    if behind is not None:
        s_wl = np.where(behind >= 0, behind, s_wl)
    a_wl = np.where(hidden_tier >= 0, 0.0, a_wl)  # hidden: the rim layer replaces it
    colour += remaining * a_wl * s_wl
    alpha = 1.0 - remaining * (1.0 - a_wl)
    shade = np.where(alpha > 1e-6, colour / np.maximum(alpha, 1e-6), s_wl)
    return alpha.astype(np.float32), shade.astype(np.float32)


# Newton has met the tier's top when the ray stands this close to it (mm); an error dz
# moves the point seen by dz * k <= dz / 4
MET_MM = 0.01
ABOVE_MM = 0.5  # how far above a meeting the ray is checked (far beyond the lookup's steps)
RAY_SAMPLES = 256  # heights a ray is sampled at where Newton did not meet the top
GOLDEN_STEPS = 16  # two sample steps (0.24 mm) down to 0.1 um, under the lookup's own steps


def _met_or_sought(grid, tg, x0, y0, kx, ky, level, z):
    """z where Newton met the tier's top coming down the ray; elsewhere the highest height at
    which the ray meets it (the first thing the camera sees along it), sought by sampling
    the ray from the grid's top down and bisecting; under the ink (covering nothing) where
    it meets none. A ray that grazes a wall leaning with it (a battered wall facing away, a
    flank along the ray) sends Newton round a cycle that ends off the top but inside the
    footprint: counted as covered, the rims of the stepped block's hidden walls were drawn
    2 px beyond their silhouettes. Or Newton meets it where it comes out of the wall, under
    the top: a strip along the rim was drawn as ink. Not trace.trace on the one tier: it stops after
    MAX_TRACE_STEPS and calls a ray still above the part a meeting, and these rays, whose
    safe steps are tiny along the wall, are the ones it runs out on (at level 18.3 it met
    the stepped block's upper tier on rays that pass it by, at 19.7-29.8 mm)."""
    rays = _Ray(grid, tg, x0, y0, kx, ky, level)
    # met, and from above: a ray whose gap grows above where Newton met the top comes out
    # of a wall there (it went in higher up, where the camera sees it)
    gap = rays.gap(z)
    off = ~(np.abs(gap) <= MET_MM) | (rays.gap(z + ABOVE_MM) > gap)
    if not off.any():
        return z
    z = z.copy()
    i = np.flatnonzero(off)
    hs = np.linspace(grid.z_max, level, RAY_SAMPLES)
    ray = rays.subset(i)
    first = np.full(i.size, -1)  # the first sample down the ray that is in the part
    best, nearest = np.zeros(i.size, int), np.full(i.size, -np.inf)  # the sample nearest it
    for j, h in enumerate(hs):
        gap = ray.gap(np.full(i.size, h))
        first[(first < 0) & (gap >= 0)] = j
        closer = gap > nearest
        best[closer], nearest[closer] = j, gap[closer]
    hit = first >= 0
    lo = hs[np.maximum(first, 0)]
    hi = np.where(first > 0, hs[np.maximum(first - 1, 0)], lo)
    # a ray that only clips a rim's corner is in the part for less than a sample's step
    clip = np.flatnonzero(~hit)
    if clip.size:
        peak, gap, above = _closest_approach(ray.subset(clip), hs, best[clip])
        met = gap >= 0
        hit[clip] = met
        lo[clip[met]], hi[clip[met]] = peak[met], above[met]
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        inside = ray.gap(mid) >= 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    z[i] = np.where(hit, lo, level - 1.0)
    return z


class _Ray:
    """Pixels' rays through one tier: gap(h), the top minus the height where each meets h."""

    def __init__(self, grid, tg, x0, y0, kx, ky, level):
        self.grid, self.tg, self.level = grid, tg, level
        self.x0, self.y0, self.kx, self.ky = x0, y0, kx, ky

    def gap(self, h):
        gx, gy = self.grid.coords(self.x0 + self.kx * (h - self.level), self.y0 + self.ky * (h - self.level))
        return lookup(self.tg.FT, gx, gy)[:, 1] - h

    def subset(self, j):
        return _Ray(self.grid, self.tg, self.x0[j], self.y0[j], self.kx[j], self.ky[j], self.level)


def _closest_approach(ray, hs, best):
    """Rays none of whose samples at heights `hs` is in the tier: where each comes closest
    to the top (the gap at its highest), sought by a golden-section search between the
    neighbours of its best sample (`best`) -> (that height, its gap, the sample above it)."""
    lo = hs[np.minimum(best + 1, hs.size - 1)]
    hi = above = hs[np.maximum(best - 1, 0)]
    r = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = hi - r * (hi - lo), lo + r * (hi - lo)  # c below d
    gc, gd = ray.gap(c), ray.gap(d)
    for _ in range(GOLDEN_STEPS):  # each step keeps one of its two points: one lookup
        lower = gc > gd  # the peak lies between lo and d
        lo, hi = np.where(lower, lo, c), np.where(lower, d, hi)
        c, d = np.where(lower, hi - r * (hi - lo), d), np.where(lower, c, lo + r * (hi - lo))
        new = ray.gap(np.where(lower, c, d))
        gc, gd = np.where(lower, new, gd), np.where(lower, gc, new)
    h = np.where(gc > gd, c, d)
    return h, np.maximum(gc, gd), above


def _borders(label):
    """The pixels of a label image that have a 4-neighbour with another label."""
    change = np.zeros(label.shape, bool)
    dh = label[:, 1:] != label[:, :-1]
    change[:, 1:] |= dh
    change[:, :-1] |= dh
    dv = label[1:, :] != label[:-1, :]
    change[1:, :] |= dv
    change[:-1, :] |= dv
    return change


# -- the frame -------------------------------------------------------------------------


def liquid_level(surface, level_mm, rig: Rig, effects: Effects) -> float:
    """The free surface's real level for a nominal `level_mm` (displacement)."""
    if effects.displacement:
        return physics.true_level(surface, level_mm, rig.tank_area_mm2)
    return float(level_mm)


def _roi(grid, surface, level, rig, pm: PixelMap):
    """Pixel rectangle whose rays can meet the part above the liquid or its waterline."""
    xmin, xmax, ymin, ymax = surface.bounds
    pad = 1.0
    box = np.array([[xmin - pad, ymin - pad], [xmax + pad, ymax + pad]])
    C = rig.centre[:2]
    t = np.clip((grid.z_max - level) / rig.height_mm, 0.0, 0.9)
    scaled = C + (box - C) / (1.0 - t)
    lo = np.minimum(box[0], scaled[0])
    hi = np.maximum(box[1], scaled[1])
    s = 8
    xs, ys = pm.x0[::s, ::s], pm.y0[::s, ::s]
    m = (xs >= lo[0]) & (xs <= hi[0]) & (ys >= lo[1]) & (ys <= hi[1])
    if not m.any():
        return None
    rows = np.nonzero(m.any(axis=1))[0]
    cols = np.nonzero(m.any(axis=0))[0]
    r0 = max(0, (rows[0] - 1) * s)
    r1 = min(rig.height, (rows[-1] + 2) * s)
    c0 = max(0, (cols[0] - 1) * s)
    c1 = min(rig.width, (cols[-1] + 2) * s)
    return r0, r1, c0, c1


def part_layer(surface, level, rig: Rig, effects: Effects, pm: PixelMap = None):
    """Coverage (alpha) and brightness (shade) of the part, full frame, float32."""
    H, W = rig.height, rig.width
    alpha = np.zeros((H, W), np.float32)
    shade = np.zeros((H, W), np.float32)
    res = part_layer_roi(surface, level, rig, effects, pm)
    if res is not None:
        (r0, r1, c0, c1), a, s = res
        alpha[r0:r1, c0:c1] = a
        shade[r0:r1, c0:c1] = s
    return alpha, shade


def part_layer_roi(surface, level, rig: Rig, effects: Effects, pm: PixelMap = None):
    """part_layer on the pixel rectangle that can see the part: ((r0, r1, c0, c1),
    alpha, shade) or None. Outside it the frame is ink."""
    pm = pm or pixel_map(rig, effects.lens_distortion)
    grid = surface_grid(surface)
    roi = _roi(grid, surface, level, rig, pm)
    if roi is None:
        return None
    r0, r1, c0, c1 = roi
    sl = (slice(r0, r1), slice(c0, c1))
    x0 = pm.x0[sl].ravel()
    y0 = pm.y0[sl].ravel()
    kx = pm.kx[sl].ravel()
    ky = pm.ky[sl].ravel()
    pix = pm.pix[sl].ravel()

    # the local free-surface level: flat, or rippling after a move
    amp = physics.ripple_amplitude(effects.ripple_mm, effects.ripple_age_s, effects.ripple_decay_s)
    if amp > 0:
        lvl = level + physics.ripple_offset(
            x0, y0, effects.ripple_mm, effects.ripple_age_s, effects.ripple_decay_s
        )
    else:
        lvl = np.full(x0.size, np.float32(level))

    # ink a pocket holds stands above the tank's level there (pockets.py)
    xw, yw = x0, y0
    if effects.trapped_ink:
        xw, yw, lvl = held_level(surface, x0, y0, kx, ky, level, lvl)

    # -- layer 1: the waterline (or, with a meniscus, the contact line) ----------------
    wl = waterline_layer(surface, grid, effects, xw, yw, kx, ky, pix, lvl)
    a_wl, lc, wtier, wwall, fgx, fgy, band = wl.alpha, wl.level, wl.tier, wl.wall, wl.fgx, wl.fgy, wl.band

    # -- layer 2: the part above the liquid, in perspective ------------------------------
    hit, zh, htier, hwall = trace_image(grid, x0, y0, kx, ky, level, pix, r1 - r0, c1 - c0)
    if effects.trapped_ink and hit.any():
        hit &= ~under_pool(surface, x0, y0, kx, ky, level, zh, hit)
    # how far (in the plane) the part the ray meets lies from where the ray crosses the
    # waterline's height: beyond two pixels the part hides what is behind it. With a
    # meniscus that height is the contact line's: part below it is under the ink.
    travel = (zh - lc) * np.hypot(kx, ky)
    occluded = hit & (travel > 2 * pix)
    a = np.where(occluded, np.float32(1.0), a_wl)

    # -- layer 3: shading of what is seen --------------------------------------------------
    s = np.zeros(x0.size, np.float32)
    if hit.any():
        dz = zh[hit] - level
        s[hit] = _shade(grid, rig, x0[hit] + kx[hit] * dz, y0[hit] + ky[hit] * dz, htier[hit], hwall[hit])
    rest = ~hit & (a > 0)
    if rest.any():
        s[rest] = _shade(grid, rig, x0[rest], y0[rest], wtier[rest], wwall[rest])

    # -- silhouettes: anti-alias where the part hides what lies behind it ---------------
    h, w = r1 - r0, c1 - c0
    # what each pixel sees: ink/waterline (-1), or a tier's top (2t) or wall (2t + 1)
    change = _borders(np.where(occluded, 2 * htier + hwall, -1).astype(np.int16).reshape(h, w))
    # A waterline on a wall that faces away from the camera (the camera is on the
    # part's side of it: grad footprint . k > 0) is hidden by the wall's rim,
    # however low the rim: the edge seen is the rim's, drawn by _silhouette.
    hidden = wwall & ((fgx * kx + fgy * ky) > 0) & band
    if change.any() or hidden.any():
        # the ramp is 2 px wide: every pixel within 1 px of a silhouette is on it
        edge = cv2.dilate(change.view(np.uint8), np.ones((3, 3), np.uint8)).astype(bool).ravel()
        edge |= hidden
        b = np.nonzero(edge)[0]
        hidden_tier = np.where(hidden[b], wtier[b], -1)
        # behind the rims: a wall the trace saw, else the waterline layer
        # (a wall met well above the liquid; nearer, the waterline ramp must stay)
        wall_seen = occluded[b] & hwall[b]
        behind = np.where(wall_seen, s[b], -1.0).astype(np.float32)
        ab, sb = _silhouette(
            surface,
            grid,
            rig,
            level,
            x0[b],
            y0[b],
            kx[b],
            ky[b],
            pix[b],
            np.where(wall_seen, np.float32(1.0), a_wl[b]),
            wtier[b],
            wwall[b],
            hidden_tier,
            behind,
        )
        a[b] = ab
        s[b] = sb
    return roi, a.reshape(r1 - r0, c1 - c0), s.reshape(r1 - r0, c1 - c0)


def render_frame(
    surface, level_mm: float, rig: Rig = None, effects: Effects = None, rng: np.random.Generator = None
) -> np.ndarray:
    """One 8-bit BGR frame with the ink at nominal level `level_mm` above the base top.

    With effects.displacement the ink's real level is lower than the nominal one
    (physics.true_level); the truth file of a scan records the real levels.
    """
    if isinstance(surface, str):
        surface = _surfaces.get(surface)
    rig = rig or Rig()
    effects = effects or Effects()
    rng = rng if rng is not None else np.random.default_rng(0)
    level = liquid_level(surface, level_mm, rig, effects)
    pm = wobbled(pixel_map(rig, effects.lens_distortion), effects, rng)
    if level != level_mm:
        # the camera is fixed to the tank: ink that has fallen d is seen from H + d, each
        # pixel's ray meeting it d further down (x0 - kx d: further from the camera's foot)
        d = np.float32(level_mm - level)
        pm = replace(pm, x0=pm.x0 - pm.kx * d, y0=pm.y0 - pm.ky * d)
    res = part_layer_roi(surface, level, rig, effects, pm)
    if effects.glare_spots > 0 or effects.dust_specks > 0:
        img = liquid_layer(rig, effects, float(level_mm), rng)
    else:
        img = np.empty((rig.height, rig.width, 3), np.float32)
        img[:] = np.asarray(rig.ink_bgr, np.float32)
    if effects.base_shows and level <= 0.0:
        _draw_base(img, rig, pm, level, effects.base_half_mm)
    if res is not None:
        # only the part's rectangle needs compositing; the rest is ink
        (r0, r1, c0, c1), alpha, shade = res
        view = img[r0:r1, c0:c1]
        a3 = alpha[..., None]
        view *= 1.0 - a3
        view += (alpha * shade)[..., None] * np.asarray(rig.part_bgr, np.float32)
    return camera_effects(img, rig, effects, pm, rng)


BASE_SHADE = 0.8  # the base's top is lit like a flat face of the part


def _draw_base(img, rig: Rig, pm: PixelMap, level, half_mm):
    """The base top (z = 0) where the ink has left it: a real bench sees it light, which is
    how commissioning finds level 0. Drawn under the part (the part is composited over it)."""
    up = -float(level)  # the base top's height above the ink
    x = pm.x0 + pm.kx * up
    y = pm.y0 + pm.ky * up
    on = (np.abs(x - 50.0) <= half_mm) & (np.abs(y - 50.0) <= half_mm)
    img[on] = BASE_SHADE * np.asarray(rig.part_bgr, np.float32)
