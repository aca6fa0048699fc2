"""The part sampled once on a fine grid: what every ray and every waterline looks up.

A surface's footprint and top functions are exact but slow (sample 3 inverts a
Bezier patch by Newton per call), and a frame asks millions of questions of
them. So each tier is sampled once per process on a lattice of at most 0.1 mm:
footprint distance and top height, their gradients, and the largest slope of
the top (which bounds a safe step of the ray march). `lookup` reads any of
these grids bilinearly at fractional grid coordinates through cv2.remap.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from . import physics


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
    level curves (physics.level_curve_curvature), as (ny, nx, 1) float32 for lookup."""
    grid = surface_grid(surface)
    out = []
    for tg in grid.tiers:
        T = tg.FT[..., 1].astype(np.float64)
        out.append(physics.level_curve_curvature(T, grid.step).astype(np.float32)[..., None])
    return out


_REMAP_COLS = 4096


def lookup(img, gx, gy, border_value=None):
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
