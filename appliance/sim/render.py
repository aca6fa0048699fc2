"""Render one camera frame of the virtual bench.

What the camera sees through each pixel: its ray leaves the camera centre C,
passes the liquid plane at P0 and, on the way, may meet the part where it
stands above the ink. The ink is opaque, so anything below the liquid is never
seen. Three layers:

1. The waterline, anti-aliased analytically. Through the pixel's liquid-plane
   point P0 the part covers a fraction a = clip(0.5 + sdf / (2 pix), 0, 1) where
   sdf = Surface.level_sdf(P0, L) (mm) and pix the pixel's size on the plane.
   The ramp is two pixels wide so that BOTH pixels straddling the waterline lie
   on it: a row's 50 % crossing, found by linear interpolation between them, is
   then exactly where sdf = 0. level_sdf is exact (analytic) in a band a few
   pixels wide around the waterline; elsewhere a grid approximation decides
   inside/outside.
2. The part above the liquid, in perspective. The ray reaches height z at
   P(z) = P0 + (C - P0) (z - L) / H. We sphere-trace it from the part's top
   down to the liquid on cached grids of the part (footprint distance and top
   height, bilinear): a step is safe when it keeps the ray out of every tier
   (horizontal distance to the footprint / the ray's horizontal speed, or the
   height gap / (1 + max slope * speed)). A ray that meets the part well away
   from P0 is occluded by it: the part hides the waterline there (walls and
   rims that face away from the optical axis).
3. Lambertian shading of the part (normal from the grids), the flat ink with
   glare and dust on it, then the camera: lamp flicker, vignetting, blur,
   noise, salt and pepper, JPEG. Lens distortion is in the per-pixel map
   (each pixel of the distorted image is traced along its true ray); stage
   wobble shifts that map by a fraction of a pixel.

Everything random is drawn from the `rng` passed in, so a frame is a pure
function of (surface, level, rig, effects, rng state). Drifting glare and
dust (the harsh preset) follow paths laid out from effects.drift_seed, so a
scan's frames share them: they move with the level and jitter per frame.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np

from ..errors import SettingError
from . import physics
from . import surfaces as _surfaces
from .rig import PixelMap, Rig, pixel_map

TOL_Z = 1e-3  # mm: a ray this close to a top has met it
MAX_TRACE_STEPS = 64


@dataclass(frozen=True)
class Effects:
    """What degrades the ideal image. All off = the clean, exact image."""

    blur_sigma_px: float = 0.0  # Gaussian optical blur
    noise_sigma: float = 0.0  # sensor noise, DN (of 255)
    salt_pepper: float = 0.0  # fraction of pixels stuck black or white
    glare_spots: int = 0  # specular highlights on the liquid
    glare_strength: float = 150.0  # DN added at a highlight's centre
    vignetting: float = 0.0  # fractional fall-off of light at the image corners
    lens_distortion: bool = False  # the frames carry the rig's lens distortion
    dust_specks: int = 0  # dust specks and small bubbles floating on the ink
    displacement: bool = False  # the ink level drops as the part emerges
    meniscus: bool = False  # ink climbs the part at the contact line
    capillary_length_mm: float = physics.CAPILLARY_LENGTH_MM
    contact_angle_deg: float = 0.0
    contact_line_curvature: bool = False  # the second meniscus model (physics.meniscus_rise_curved)
    ripple_mm: float = 0.0  # amplitude of the free surface's oscillation just after a move
    ripple_age_s: float = 0.0  # time since the move stopped (VirtualCamera sets it)
    ripple_decay_s: float = 0.6
    base_shows: bool = False  # the base top, once at or above the ink, is drawn (lit, like the part)
    base_half_mm: float = 60.0  # half the side of the square base, centred under the parts
    # A scan's worth of nuisances that move (the harsh bench). Off, glare and dust are drawn
    # afresh in every frame; on, they follow paths laid out once (seeded by drift_seed) that
    # drift as the level changes, jitter from frame to frame (the frame's rng), and each glare
    # blob flickers and now and then vanishes: a bright thing that comes and goes.
    drifting: bool = False
    drift_seed: int = 0
    flicker: float = 0.0  # the lamp's brightness per frame: x (1 + u * flicker), u in [-1, 1]
    jpeg_quality: int = 0  # the frame passes through JPEG at this quality (0: it does not)
    wobble_mm: float = 0.0  # lateral stage play: each frame sees the part shifted up to this far

    def to_json(self):
        return asdict(self)


PRESETS = {
    "clean": Effects(),
    "optics": Effects(blur_sigma_px=0.7, vignetting=0.25, lens_distortion=True),
    "realistic": Effects(
        blur_sigma_px=0.8,
        noise_sigma=2.5,
        salt_pepper=2e-5,
        glare_spots=3,
        vignetting=0.25,
        lens_distortion=True,
        dust_specks=30,
    ),
    "physics": Effects(
        blur_sigma_px=0.8,
        noise_sigma=2.5,
        salt_pepper=2e-5,
        glare_spots=3,
        vignetting=0.25,
        lens_distortion=True,
        dust_specks=30,
        displacement=True,
        meniscus=True,
    ),
    # a second ink, another meniscus model: wets at 35 deg (a depression on flatter faces),
    # the contact line's own curvature raising the meniscus in pits and lowering it on ridges
    "physics2": Effects(
        blur_sigma_px=0.8,
        noise_sigma=2.5,
        salt_pepper=2e-5,
        glare_spots=3,
        vignetting=0.25,
        lens_distortion=True,
        dust_specks=30,
        displacement=True,
        meniscus=True,
        capillary_length_mm=2.3,
        contact_angle_deg=35.0,
        contact_line_curvature=True,
    ),
    # Everything at once, moving: glare that drifts, jitters and flickers from frame to frame,
    # drifting dust and bubbles, salt and pepper, JPEG q85, 1.5 % lamp flicker, 0.05 mm of
    # stage wobble no calibration knows about, a rippling surface, and a meniscus that is not
    # the first model's: another capillary length and the contact line's own curvature. Its
    # contact angle stays 0: a depression on flat faces (physics2) is the meniscus model's
    # open question (benches/meniscus.py), not the images'.
    "harsh": Effects(
        blur_sigma_px=1.3,
        noise_sigma=6.0,
        salt_pepper=3e-4,
        glare_spots=6,
        glare_strength=200.0,
        vignetting=0.4,
        lens_distortion=True,
        dust_specks=120,
        displacement=True,
        meniscus=True,
        capillary_length_mm=2.5,
        contact_line_curvature=True,
        ripple_mm=0.05,
        ripple_age_s=0.5,
        drifting=True,
        drift_seed=18,
        flicker=0.015,
        jpeg_quality=85,
        wobble_mm=0.05,
    ),
}


def effects_preset(name: str) -> Effects:
    try:
        return PRESETS[name]
    except KeyError:
        raise SettingError(
            "effects", f"unknown effects preset {name!r}; known: {', '.join(PRESETS)}"
        ) from None


# -- cached grids of a part ---------------------------------------------------


@dataclass
class TierGrid:
    FT: np.ndarray  # (ny, nx, 2) float32: footprint sdf (mm, > 0 inside), top height
    N: np.ndarray  # (ny, nx, 4) float32: d top/dx, d top/dy, d sdf/dx, d sdf/dy
    slope_max: float  # max |grad top| over the footprint (bounds the safe step)


@dataclass
class SurfaceGrid:
    x0: float
    y0: float
    step: float
    margin: float
    tiers: list
    z_max: float

    def coords(self, x, y):
        return (
            ((x - self.x0) / self.step).astype(np.float32),
            ((y - self.y0) / self.step).astype(np.float32),
        )


@functools.lru_cache(maxsize=4)  # ~25 MB per tier of a 100 mm part
def surface_grid(surface) -> SurfaceGrid:
    """Sample every tier of a part on a fine grid, once per process."""
    xmin, xmax, ymin, ymax = surface.bounds
    extent = max(xmax - xmin, ymax - ymin)
    step = min(0.1, extent / 800.0)
    margin = max(2.0, 20 * step)
    xs = np.arange(xmin - margin, xmax + margin + step, step)
    ys = np.arange(ymin - margin, ymax + margin + step, step)
    X, Y = np.meshgrid(xs, ys)
    tiers = []
    z_max = 0.0
    for t in surface.tiers:
        F = np.asarray(t.footprint(X, Y), float)
        T = np.broadcast_to(np.asarray(t.top(X, Y), float), X.shape)
        Ty, Tx = np.gradient(T, step)
        Fy, Fx = np.gradient(F, step)
        near = F >= -2 * step
        slope = float(np.max(np.hypot(Tx, Ty)[near])) if near.any() else 0.0
        inside = F >= 0
        if inside.any():
            z_max = max(z_max, float(np.max(T[inside])))
        FT = np.dstack([F, T]).astype(np.float32)
        Nrm = np.dstack([Tx, Ty, Fx, Fy]).astype(np.float32)
        tiers.append(TierGrid(FT, Nrm, slope * 1.05 + 1e-3))
    return SurfaceGrid(float(xs[0]), float(ys[0]), step, margin, tiers, z_max)


@functools.lru_cache(maxsize=4)
def curvature_grid(surface) -> list:
    """Per tier, on surface_grid's lattice: the in-plane curvature (1/mm) of the top's
    level curves (physics.level_curve_curvature), as (ny, nx, 1) float32 for _lookup."""
    grid = surface_grid(surface)
    out = []
    for tg in grid.tiers:
        T = tg.FT[..., 1].astype(np.float64)
        out.append(physics.level_curve_curvature(T, grid.step).astype(np.float32)[..., None])
    return out


def _contact_curvature(surface, grid, x, y, tier):
    """Curvature of the contact line through plane points x, y on each one's tier's top."""
    kg = curvature_grid(surface)
    gx, gy = grid.coords(x, y)
    out = np.zeros(x.size, np.float32)
    for ti, k in enumerate(kg):
        sel = tier == ti
        if sel.any():
            out[sel] = _lookup(k, gx[sel], gy[sel], (0.0, 0.0, 0.0, 0.0))[:, 0]
    return out


_REMAP_COLS = 4096


def _lookup(img, gx, gy, border_value=None):
    """Bilinear lookup of a (ny, nx, c) grid at fractional grid coordinates.

    cv2.remap is ~10x faster than scipy here; it wants 2-D maps no larger than
    32767 on a side, so the points are laid out in rows of 4096.
    """
    n = gx.size
    if n == 0:
        return np.zeros((0, img.shape[2] if img.ndim == 3 else 1), np.float32)
    rows = -(-n // _REMAP_COLS)
    pad = rows * _REMAP_COLS - n
    mx = np.pad(gx, (0, pad)).reshape(rows, _REMAP_COLS)
    my = np.pad(gy, (0, pad)).reshape(rows, _REMAP_COLS)
    if border_value is None:
        out = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    else:
        out = cv2.remap(
            img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=border_value
        )
    return out.reshape(rows * _REMAP_COLS, -1)[:n]


def _lookup_FT(grid, tg, x, y):
    gx, gy = grid.coords(x, y)
    # Off the grid we are at least `margin` from any footprint: a safe, finite distance.
    out = _lookup(tg.FT, gx, gy, (-grid.margin, 0.0, 0.0, 0.0))
    return out[:, 0], out[:, 1]


# -- the perspective ray march --------------------------------------------------


def trace(grid: SurfaceGrid, px, py, kx, ky, level):
    """Sphere-trace rays from the camera down to the liquid.

    px, py: where each ray meets the liquid plane (mm); kx, ky: its horizontal
    travel per mm of height. Returns (hit, z, tier, wall): whether the ray meets
    the part at or above `level`, the height of the first meeting, the tier
    index and whether it met a wall (side of a tier) rather than a top.
    """
    n = px.size
    px = px.astype(np.float32, copy=False)
    py = py.astype(np.float32, copy=False)
    k = np.hypot(kx, ky).astype(np.float32)
    kinv = 1.0 / np.maximum(k, 1e-6)
    hit = np.zeros(n, bool)
    zout = np.full(n, np.float32(level))
    tier = np.full(n, -1, np.int16)
    wall = np.zeros(n, bool)
    if n == 0 or grid.z_max < level:
        return hit, zout, tier, wall
    idx = np.arange(n)
    z = np.full(n, np.float32(grid.z_max + 2 * TOL_Z))
    L = np.float32(level)
    for _ in range(MAX_TRACE_STEPS):
        if idx.size == 0:
            break
        dz = z - L
        xs = px[idx] + kx[idx] * dz
        ys = py[idx] + ky[idx] * dz
        ka, kia = k[idx], kinv[idx]
        step = np.full(idx.size, np.inf, np.float32)
        best_T = np.full(idx.size, -np.inf, np.float32)
        best_F = np.zeros(idx.size, np.float32)
        best_t = np.full(idx.size, -1, np.int16)
        for ti, tg in enumerate(grid.tiers):
            F, T = _lookup_FT(grid, tg, xs, ys)
            in_fp = F >= 0
            inside = in_fp & (z <= T + TOL_Z)
            s = np.where(in_fp, (z - T) / (1.0 + tg.slope_max * ka), (1e-3 - F) * kia)
            np.minimum(step, s, out=step)
            better = inside & (T > best_T)
            best_t[better] = ti
            best_T[better] = T[better]
            best_F[better] = F[better]
        met = best_t >= 0
        if met.any():
            j = idx[met]
            hit[j] = True
            zout[j] = z[met]
            tier[j] = best_t[met]
            # a wall: the ray has just crossed the footprint's edge below the top
            # (not a top overshot by the grid's interpolation)
            wall[j] = (best_T[met] - z[met] > 2 * TOL_Z) & (best_F[met] < 0.02)
        z_next = z - np.maximum(step, 0)
        # A safe step that would take the ray below the liquid proves it meets
        # nothing above it: the pixel sees ink (or the waterline layer decides).
        keep = ~met & (z_next > L)
        stalled = keep & (step < 1e-5)
        if stalled.any():  # grazing a top: accept the meeting
            j = idx[stalled]
            hit[j] = True
            zout[j] = z[stalled]
            tier[j] = best_t[stalled].clip(0)
            keep &= ~stalled
        idx = idx[keep]
        z = z_next[keep]
    if idx.size:  # out of steps: still above the part, call it met
        hit[idx] = True
        zout[idx] = z
        tier[idx] = 0
    return hit, zout, tier, wall


COARSE = 4  # px: the ray march runs on every 4th pixel first


def trace_image(grid, x0, y0, kx, ky, level, pix, h, w, s=COARSE):
    """trace() for an h x w block of pixels, coarse to fine.

    Rays are marched on every s-th pixel first. Inside a coarse cell whose four
    corners (and those of its neighbours) all see the same tier's top well
    above the liquid - or all see nothing - the fine pixels take the corners'
    answer, with the height interpolated bilinearly (the top is smooth there;
    an error dz in height moves the point seen by dz * k, far below a pixel).
    Every other pixel - near silhouettes, walls, tier changes, the waterline -
    is marched on its own.
    """
    n = h * w
    if h < 2 * s or w < 2 * s:
        return trace(grid, x0, y0, kx, ky, level)
    ri = np.unique(np.minimum(np.arange(0, h + s - 1, s), h - 1))
    ci = np.unique(np.minimum(np.arange(0, w + s - 1, s), w - 1))
    sub = (ri[:, None] * w + ci[None, :]).ravel()
    hc, wc = ri.size, ci.size
    hit_c, z_c, t_c, w_c = trace(grid, x0[sub], y0[sub], kx[sub], ky[sub], level)
    k_c = np.hypot(kx[sub], ky[sub])
    occ_c = hit_c & ~w_c & ((z_c - level) * k_c > 4 * pix[sub])
    label = np.where(occ_c, t_c, np.where(hit_c, -2, -1)).astype(np.int16).reshape(hc, wc)
    uniform = (
        (label[:-1, :-1] == label[1:, :-1])
        & (label[:-1, :-1] == label[:-1, 1:])
        & (label[:-1, :-1] == label[1:, 1:])
        & (label[:-1, :-1] != -2)
    )
    uniform = cv2.erode(
        uniform.view(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=1
    ).astype(bool)
    # the coarse cell of each fine row / column
    rcell = np.minimum(np.searchsorted(ri, np.arange(h), side="right") - 1, hc - 2)
    ccell = np.minimum(np.searchsorted(ci, np.arange(w), side="right") - 1, wc - 2)
    fr = ((np.arange(h) - ri[rcell]) / (ri[rcell + 1] - ri[rcell])).astype(np.float32)
    fc = ((np.arange(w) - ci[ccell]) / (ci[ccell + 1] - ci[ccell])).astype(np.float32)
    uni = uniform[rcell][:, ccell].ravel()
    lab = label[:-1, :-1][rcell][:, ccell].ravel()
    zc = z_c.reshape(hc, wc)
    z00 = zc[rcell][:, ccell]
    z01 = zc[rcell][:, ccell + 1]
    z10 = zc[rcell + 1][:, ccell]
    z11 = zc[rcell + 1][:, ccell + 1]
    a, b = fr[:, None], fc[None, :]
    zi = ((1 - a) * ((1 - b) * z00 + b * z01) + a * ((1 - b) * z10 + b * z11)).ravel()
    hit = uni & (lab >= 0)
    z = np.where(hit, zi, np.float32(level)).astype(np.float32)
    tier = np.where(hit, lab, -1).astype(np.int16)
    wall = np.zeros(n, bool)
    todo = np.nonzero(~uni)[0]
    if todo.size:
        hh, zz, tt, ww = trace(grid, x0[todo], y0[todo], kx[todo], ky[todo], level)
        hit[todo] = hh
        z[todo] = zz
        tier[todo] = tt
        wall[todo] = ww
    return hit, z, tier, wall


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
        d = _lookup(tg.N, gx, gy)
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
        z = _lookup(tg.FT, gx, gy)[:, 1].astype(np.float64)
        for _ in range(6):
            px, py = x0d + kxd * (z - level), y0d + kyd * (z - level)
            gx, gy = grid.coords(px, py)
            T = _lookup(tg.FT, gx, gy)[:, 1]
            d = _lookup(tg.N, gx, gy)
            dg = d[:, 0] * kxd + d[:, 1] * kyd - 1.0
            dg = np.where(np.abs(dg) < 0.05, -0.05, dg)  # grazing: damp the step
            z = z - np.clip((T - z) / dg, -5.0, 5.0)
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


def _exact_level_sdf(surface, grid, x, y, level, eps=1e-4):
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
        ft = _lookup(tg.FT, gx, gy, (-grid.margin, 0.0, 0.0, 0.0))
        d = _lookup(tg.N, gx, gy)
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


def _approx_sdf(grid, x, y, level):
    """Grid approximation of level_sdf and of which tier/kind of edge wins."""
    best = np.full(x.size, -np.inf, np.float32)
    tier = np.zeros(x.size, np.int16)
    wall = np.zeros(x.size, bool)
    slope = np.zeros(x.size, np.float32)
    fgx = np.zeros(x.size, np.float32)
    fgy = np.zeros(x.size, np.float32)
    gx, gy = grid.coords(x, y)
    for ti, tg in enumerate(grid.tiers):
        ft = _lookup(tg.FT, gx, gy, (-grid.margin, 0.0, 0.0, 0.0))
        d = _lookup(tg.N, gx, gy)
        g = np.hypot(d[:, 0], d[:, 1])
        F, T = ft[:, 0], ft[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            dtop = np.where(g > 1e-6, (T - level) / g, np.where(T >= level, 1e3, -1e3)).astype(np.float32)
        v = np.minimum(F, dtop)
        better = v > best
        best[better] = v[better]
        tier[better] = ti
        wall[better] = (F < dtop)[better]
        slope[better] = g[better]
        fgx[better] = d[better, 2]
        fgy[better] = d[better, 3]
    return best, tier, wall, slope, fgx, fgy


def _top_height(grid, x, y, tier):
    """Height of each point's tier's top (continued past its footprint on the grid)."""
    gx, gy = grid.coords(x, y)
    out = np.zeros(x.size, np.float32)
    for ti, tg in enumerate(grid.tiers):
        sel = tier == ti
        if sel.any():
            out[sel] = _lookup(tg.FT, gx[sel], gy[sel], (-grid.margin, 0.0, 0.0, 0.0))[:, 1]
    return out


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

    # -- layer 1: the waterline (or, with a meniscus, the contact line) ----------------
    approx, wtier, wwall, wslope, fgx, fgy = _approx_sdf(grid, x0, y0, lvl)
    xc, yc, lc = x0, y0, lvl
    if effects.meniscus:
        # The contact line on the top sits h(beta) above the free surface, beta the top's
        # slope where the contact line is (found by iterating from the slope at the free
        # surface's own level curve). A wall does not drag the ink over the top: at a
        # sharp edge the contact line pins, so the top near a wall comes out with its own
        # slope's rise, and on the wall itself the ink climbs h(90 deg) - which only moves
        # where a wall facing the camera shows its waterline.
        # With the second model the rise also depends on the contact line's own curvature
        # there (the top's level curve through the contact point).
        theta = math.radians(effects.contact_angle_deg)
        l_c = effects.capillary_length_mm

        def rise(b, x=None, y=None, tier=None):
            if x is None or not effects.contact_line_curvature:
                return physics.meniscus_rise(b, l_c, theta).astype(np.float32)
            kappa = _contact_curvature(surface, grid, x, y, tier)
            return physics.meniscus_rise_curved(b, kappa, l_c, theta).astype(np.float32)

        h = rise(np.arctan(wslope), x0, y0, wtier)
        for _ in range(2):
            lc = lvl + h
            xs, ys = x0 + kx * h, y0 + ky * h
            approx, wtier, wwall, wslope, fgx, fgy = _approx_sdf(grid, xs, ys, lc)
            h = rise(np.arctan(wslope), xs, ys, wtier)
        lc = lvl + h
        # on a wall the ink climbs h(90 deg), but never past the wall's top edge
        seen_h = h.copy()
        if wwall.any():
            rim = _top_height(grid, x0[wwall], y0[wwall], wtier[wwall]) - lvl[wwall]
            seen_h[wwall] = np.clip(rim, 0.0, rise(np.pi / 2))
        # the contact line is seen_h above the free surface: seen in perspective from there
        xc, yc = x0 + kx * seen_h, y0 + ky * seen_h
        approx, wtier, wwall, wslope, fgx, fgy = _approx_sdf(grid, xc, yc, lc)
    band = np.abs(approx) < 4 * pix + 0.02
    sdf = approx.copy()
    if band.any():
        sdf[band] = _exact_level_sdf(surface, grid, xc[band], yc[band], lc[band])
    a_wl = np.clip(0.5 + sdf / (2 * pix), 0.0, 1.0).astype(np.float32)

    # -- layer 2: the part above the liquid, in perspective ------------------------------
    hit, zh, htier, hwall = trace_image(grid, x0, y0, kx, ky, level, pix, r1 - r0, c1 - c0)
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
    label = np.where(occluded, 2 * htier + hwall, -1).astype(np.int16).reshape(h, w)
    change = np.zeros((h, w), bool)
    dh = label[:, 1:] != label[:, :-1]
    change[:, 1:] |= dh
    change[:, :-1] |= dh
    dv = label[1:, :] != label[:-1, :]
    change[1:, :] |= dv
    change[:-1, :] |= dv
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


def _fresh_glare(W, H, effects, rng, level_mm):
    """Glare drawn afresh for this frame: (cx, cy, sx, sy, peak) per blob."""
    for _ in range(effects.glare_spots):
        cx, cy = rng.uniform(0, W), rng.uniform(0, H)
        sx, sy = rng.uniform(15, 70), rng.uniform(15, 70)
        yield cx, cy, sx, sy, effects.glare_strength * rng.uniform(0.5, 1.0)


def _fresh_dust(W, H, effects, rng, level_mm):
    """Dust and bubbles drawn afresh for this frame: (cx, cy, radius, is_bubble, shade)."""
    for _ in range(effects.dust_specks):
        cx, cy = rng.uniform(0, W), rng.uniform(0, H)
        rad = rng.uniform(0.8, 3.5)
        bubble = rng.uniform() < 0.4
        yield cx, cy, rad, bubble, (1.0 if bubble else rng.uniform(0.6, 1.4))


DRIFT_JITTER_PX = 6.0  # frame-to-frame wander of a drifting glare blob (ripples, the lamp)


def _layout(effects, n, speed_px_per_mm):
    """Where drifting things start and how fast they move, the same for every frame of a scan."""
    lay = np.random.default_rng([effects.drift_seed, n])
    start = lay.uniform(0.0, 1.0, (n, 2))
    angle = lay.uniform(0.0, 2 * np.pi, n)
    speed = lay.uniform(*speed_px_per_mm, n)
    return start, speed[:, None] * np.column_stack([np.cos(angle), np.sin(angle)]), lay


GLARE_WINDOW = 0.6  # drifting glare wanders over the middle 60 % of the frame, where parts are


def _drifting_glare(W, H, effects, rng, level_mm):
    start, vel, lay = _layout(effects, effects.glare_spots, (8.0, 40.0))
    size = lay.uniform(15, 70, (effects.glare_spots, 2))
    w, h = GLARE_WINDOW * W, GLARE_WINDOW * H
    for (x0, y0), (vx, vy), (sx, sy) in zip(start, vel, size):
        jx, jy = rng.normal(0.0, DRIFT_JITTER_PX, 2)
        grow = rng.uniform(0.8, 1.2)
        peak = effects.glare_strength * rng.uniform(0.4, 1.0)
        if rng.uniform() < 0.35:  # the highlight is gone in this frame
            continue
        yield (
            (W - w) / 2 + (x0 * w + vx * level_mm + jx) % w,
            (H - h) / 2 + (y0 * h + vy * level_mm + jy) % h,
            sx * grow,
            sy * grow,
            peak,
        )


def _drifting_dust(W, H, effects, rng, level_mm):
    start, vel, lay = _layout(effects, effects.dust_specks, (3.0, 15.0))
    rad = lay.uniform(0.8, 3.5, effects.dust_specks)
    bubble = lay.uniform(size=effects.dust_specks) < 0.4
    shade = lay.uniform(0.6, 1.4, effects.dust_specks)
    for i in range(effects.dust_specks):
        jx, jy = rng.normal(0.0, 1.0, 2)
        yield (
            (start[i, 0] * W + vel[i, 0] * level_mm + jx) % W,
            (start[i, 1] * H + vel[i, 1] * level_mm + jy) % H,
            rad[i],
            bubble[i],
            shade[i],
        )


def _liquid_layer(rig, effects, level_mm, rng):
    """The ink as the camera sees it: flat dark blue, plus glare and dust on it."""
    H, W = rig.height, rig.width
    ink = np.empty((H, W, 3), np.float32)
    ink[:] = np.asarray(rig.ink_bgr, np.float32)
    glare = _drifting_glare if effects.drifting else _fresh_glare
    for cx, cy, sx, sy, peak in glare(W, H, effects, rng, level_mm):
        # a specular highlight: a soft, slightly elongated blob of the lamp's colour
        r = int(3.5 * max(sx, sy))
        xa, xb = int(max(0, cx - r)), int(min(W, cx + r + 1))
        ya, yb = int(max(0, cy - r)), int(min(H, cy + r + 1))
        if xa >= xb or ya >= yb:
            continue
        u = np.arange(xa, xb, dtype=np.float32) - cx
        v = np.arange(ya, yb, dtype=np.float32) - cy
        blob = peak * np.exp(-0.5 * ((v[:, None] / sy) ** 2 + (u[None, :] / sx) ** 2))
        ink[ya:yb, xa:xb] += blob[..., None] * np.array([1.0, 0.97, 0.95], np.float32)
    dust = _drifting_dust if effects.drifting else _fresh_dust
    for cx, cy, rad, bubble, shade in dust(W, H, effects, rng, level_mm):
        r = int(rad + 3)
        xa, xb = int(max(0, cx - r)), int(min(W, cx + r + 1))
        ya, yb = int(max(0, cy - r)), int(min(H, cy + r + 1))
        if xa >= xb or ya >= yb:
            continue
        u = np.arange(xa, xb, dtype=np.float32) - cx
        v = np.arange(ya, yb, dtype=np.float32) - cy
        d = np.sqrt(v[:, None] ** 2 + u[None, :] ** 2)
        cover = np.clip(rad + 0.5 - d, 0, 1)[..., None]
        if bubble:
            # a bubble: bright rim around a dark centre
            rim = np.clip(1.0 - np.abs(d - rad * 0.8) / max(rad * 0.35, 0.6), 0, 1)[..., None]
            colour = np.asarray(rig.ink_bgr, np.float32) * 0.6 + 140.0 * rim
        else:
            # dust: grey-brown speck
            colour = np.array([90, 100, 110], np.float32) * shade
        patch = ink[ya:yb, xa:xb]
        patch[:] = patch * (1 - cover) + colour * cover
    return ink


def _wobbled(pm: PixelMap, effects: Effects, rng) -> PixelMap:
    """The pixel map of a frame whose part sits up to wobble_mm off where the stage says."""
    if effects.wobble_mm <= 0:
        return pm
    r = effects.wobble_mm * math.sqrt(rng.uniform())
    a = rng.uniform(0.0, 2 * math.pi)
    return replace(pm, x0=pm.x0 - np.float32(r * math.cos(a)), y0=pm.y0 - np.float32(r * math.sin(a)))


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
    pm = _wobbled(pixel_map(rig, effects.lens_distortion), effects, rng)
    res = part_layer_roi(surface, level, rig, effects, pm)
    if effects.glare_spots > 0 or effects.dust_specks > 0:
        img = _liquid_layer(rig, effects, float(level_mm), rng)
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


def camera_effects(img, rig: Rig, effects: Effects, pm: PixelMap, rng) -> np.ndarray:
    """What the lens and sensor do to the light: vignetting, blur, noise, stuck pixels.
    `img` is float32 BGR (0..255), modified in place; returns 8-bit BGR."""
    if effects.flicker > 0:
        img *= np.float32(1.0 + effects.flicker * rng.uniform(-1.0, 1.0))
    if effects.vignetting > 0:
        img *= (1.0 - effects.vignetting * pm.vignette_r2)[..., None]
    if effects.blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), effects.blur_sigma_px)
    if effects.noise_sigma > 0:
        # OpenCV's generator is ~2x faster than numpy's on 9.4 M samples; seeding it
        # from rng keeps the frame a function of the rng's state (its state is per thread)
        cv2.setRNGSeed(int(rng.integers(1, 2**31)))
        noise = np.empty_like(img)
        cv2.randn(noise, 0.0, float(effects.noise_sigma))
        cv2.add(img, noise, dst=img)
    if effects.salt_pepper > 0:
        n = int(rng.binomial(img.shape[0] * img.shape[1], effects.salt_pepper))
        if n:
            r = rng.integers(0, img.shape[0], n)
            c = rng.integers(0, img.shape[1], n)
            img[r, c] = np.where(rng.uniform(size=n) < 0.5, 0.0, 255.0)[:, None]
    # round and saturate to 8 bits (convertScaleAbs would fold negatives up: clamp first)
    cv2.max(img, 0.0, dst=img)
    out = cv2.convertScaleAbs(img)
    if effects.jpeg_quality:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(effects.jpeg_quality)])
        out = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    return out
