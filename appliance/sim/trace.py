"""Where a camera ray first meets the part above the ink: the sphere tracer.

A pixel's ray leaves the camera centre C and crosses the liquid plane at P0;
at height z it is at P(z) = P0 + (C - P0) (z - L) / H, i.e. it travels (kx, ky)
mm sideways per mm of height. We march it from above the part's top down to
the liquid on the cached grids (partgrid.py): a step is safe when it keeps the
ray out of every tier (horizontal distance to the footprint / the ray's
horizontal speed, or the height gap / (1 + max slope * speed)). trace_image
does this for a block of pixels, coarse to fine, marching only the pixels
whose neighbourhood is not uniform.
"""

from __future__ import annotations

import cv2
import numpy as np

from .partgrid import SurfaceGrid, lookup

TOL_Z = 1e-3  # mm: a ray this close to a top has met it
MAX_TRACE_STEPS = 64


def _lookup_FT(grid, tg, x, y):
    gx, gy = grid.coords(x, y)
    # Off the grid we are at least `margin` from any footprint: a safe, finite distance.
    out = lookup(tg.FT, gx, gy, (-grid.margin, 0.0, 0.0, 0.0))
    return out[:, 0], out[:, 1]


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
