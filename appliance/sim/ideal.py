"""Ideal waterlines of a known part: the exact level curves, no camera, no ink physics.

The surface room's ceiling is measured on these. For each level we raster the
part's `level_sdf` at `resolution_mm`, trace the boundary of the exposed pixels
(OpenCV, outer boundaries and holes), then pull every traced point onto the
true zero set by Newton steps along the sdf's gradient: the points are exact to
well under a micrometre, the raster only decides how dense they are.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..vision.types import Waterline, signed_area
from . import physics

_EPS = 1e-4


def _project_to_zero_set(surface, pts, level, iterations=6):
    """Newton steps p -= s(p) grad s / |grad s|^2 onto level_sdf(p) = 0."""
    p = pts.copy()
    for _ in range(iterations):
        x, y = p[:, 0], p[:, 1]
        s = surface.level_sdf(x, y, level)
        gx = (surface.level_sdf(x + _EPS, y, level) - surface.level_sdf(x - _EPS, y, level)) / (2 * _EPS)
        gy = (surface.level_sdf(x, y + _EPS, level) - surface.level_sdf(x, y - _EPS, level)) / (2 * _EPS)
        g2 = gx * gx + gy * gy
        ok = np.isfinite(s) & (g2 > 1e-12)
        step = np.where(ok, s / np.where(ok, g2, 1.0), 0.0)
        # a step longer than two raster cells means a kink of the sdf: do not jump across it
        step = np.clip(step, -0.5, 0.5)
        p[:, 0] -= step * gx
        p[:, 1] -= step * gy
    return p


def ideal_waterline(surface, level, resolution_mm=0.05) -> Waterline:
    xmin, xmax, ymin, ymax = surface.bounds
    pad = 3 * resolution_mm
    xs = np.arange(xmin - pad, xmax + pad + resolution_mm / 2, resolution_mm)
    ys = np.arange(ymin - pad, ymax + pad + resolution_mm / 2, resolution_mm)
    X, Y = np.meshgrid(xs, ys)
    exposed = (surface.level_sdf(X, Y, level) > 0).astype(np.uint8)
    contours, hierarchy = cv2.findContours(exposed, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    loops = []
    for c, h in zip(contours, hierarchy[0] if hierarchy is not None else []):
        if len(c) < 3:
            continue
        ij = c[:, 0, :].astype(float)
        pts = np.column_stack([xs[0] + ij[:, 0] * resolution_mm, ys[0] + ij[:, 1] * resolution_mm])
        pts = _project_to_zero_set(surface, pts, level)
        is_hole = h[3] >= 0
        area = signed_area(pts)
        if (area > 0) == is_hole:  # outer boundaries CCW, holes CW
            pts = pts[::-1]
        loops.append(pts)
    return Waterline(float(level), loops)


def ideal_waterlines(surface, levels, resolution_mm=0.05) -> list[Waterline]:
    """One exact Waterline per level (levels in the object frame, mm above the base)."""
    return [ideal_waterline(surface, lv, resolution_mm) for lv in levels]


class _MeniscusView:
    """A part seen through the ink's meniscus: its level_sdf at L is that of the
    contact line, the level curve at L + h(beta) of the top (walls stay walls)."""

    def __init__(self, surface, capillary_length_mm, contact_angle_rad, curved=False):
        self.s = surface
        self.bounds = surface.bounds
        self.l_c, self.theta, self.curved = capillary_length_mm, contact_angle_rad, curved

    def _gradient(self, x, y, e=1e-4):
        s = self.s
        return (
            (s.height(x + e, y) - s.height(x - e, y)) / (2 * e),
            (s.height(x, y + e) - s.height(x, y - e)) / (2 * e),
        )

    def _curvature(self, x, y):
        """The contact line's curvature as the renderer takes it (partgrid.curvature_grid)."""
        from .partgrid import curvature_grid, surface_grid

        grid = surface_grid(self.s)
        k = np.asarray(curvature_grid(self.s)[0][..., 0], float)
        gx, gy = grid.coords(np.asarray(x, float).ravel(), np.asarray(y, float).ravel())
        from scipy import ndimage

        return ndimage.map_coordinates(k, [gy, gx], order=1, mode="nearest").reshape(np.shape(x))

    def level_sdf(self, x, y, level):
        gx, gy = self._gradient(x, y)
        beta = np.arctan(np.hypot(gx, gy))
        if self.curved:
            h = physics.meniscus_rise_curved(beta, self._curvature(x, y), self.l_c, self.theta)
        else:
            h = physics.meniscus_rise(beta, self.l_c, self.theta)
        return self.s.level_sdf(x, y, level + h)


def meniscus_waterlines(
    surface, levels, capillary_length_mm=2.7, contact_angle_rad=0.0, resolution_mm=0.05, curved=False
) -> list[Waterline]:
    """Waterlines as the ink's contact lines, observed straight down (no perspective).

    Valid on the sculptured top away from walls (there the renderer lets the ink
    climb the wall instead): meant for parts like the calibration references. `curved`: the
    second meniscus model (the contact line's own curvature, physics.meniscus_rise_curved)."""
    view = _MeniscusView(surface, capillary_length_mm, contact_angle_rad, curved)
    return [ideal_waterline(view, lv, resolution_mm) for lv in levels]
