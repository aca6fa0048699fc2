"""The dissertation's surface methods (chapter 3, step 5), kept as the baseline.

Input: scattered slice points (x, y, level) from edge pixels, and for "as
captured" which grid cells each frame showed above the liquid. Output: a
height map on the dissertation's 50 x 50 grid over the part.

- as captured: no enhancement. Each cell gets the level of the highest frame
  in which it was above the liquid: the stack of extruded slices the
  dissertation assembled in AutoCAD ("given elevation"), quantised to the step.
- spline: piecewise-cubic interpolation of the scattered points
  (scipy's Clough-Tocher `griddata(..., 'cubic')`, MATLAB griddata's
  counterpart), nearest value outside the points' convex hull.
- nearest: nearest-neighbour interpolation of the scattered points.
- least squares of degree 1, 2, 3: a global polynomial (eqs 3-1, 3-9, 3-13),
  solved from the normal equations (eqs 3-5, 3-12, 3-16). We centre and scale
  x, y to [-1, 1] first: on raw millimetres the cubic's normal matrix has a
  condition number near 1e17 and the solve would be noise.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CloughTocher2DInterpolator
from scipy.spatial import cKDTree

from .heightmap import HeightMap

METHODS = ("captured", "spline", "nearest", "lsq1", "lsq2", "lsq3")
LABELS = {
    "captured": "As captured",
    "spline": "Spline interpolation",
    "nearest": "Nearest interpolation",
    "lsq1": "Least squares, degree 1",
    "lsq2": "Least squares, degree 2",
    "lsq3": "Least squares, degree 3",
}


def seed_grid(points_xy: np.ndarray, n: int = 50):
    """The n x n grid spanning the bounding box of the slice points."""
    if len(points_xy) < 3:
        raise ValueError("need at least three slice points to place a grid")
    x = np.linspace(points_xy[:, 0].min(), points_xy[:, 0].max(), n)
    y = np.linspace(points_xy[:, 1].min(), points_xy[:, 1].max(), n)
    return x, y


def as_captured(x, y, levels, exposed) -> HeightMap:
    """exposed: (K, ny, nx) bool, cell above the liquid in frame k at levels[k]."""
    levels = np.asarray(levels, float)
    z = np.full((len(y), len(x)), -np.inf)
    for level, ex in zip(levels, exposed):
        z = np.where(ex, np.maximum(z, level), z)
    return HeightMap(x, y, np.where(np.isfinite(z), z, np.nan))


def nearest(x, y, pts) -> HeightMap:
    X, Y = np.meshgrid(x, y)
    _, i = cKDTree(pts[:, :2]).query(np.column_stack([X.ravel(), Y.ravel()]))
    return HeightMap(x, y, pts[i, 2].reshape(X.shape))


def spline(x, y, pts) -> HeightMap:
    """Clough-Tocher on the points' Delaunay triangulation (what griddata 'cubic' does,
    built once here: on 100 k slice points the triangulation's set-up is the cost)."""
    X, Y = np.meshgrid(x, y)
    z = CloughTocher2DInterpolator(pts[:, :2], pts[:, 2])(X, Y)
    hole = ~np.isfinite(z)
    if hole.any():
        z[hole] = nearest(x, y, pts).z[hole]
    return HeightMap(x, y, z)


def poly_terms(u, v, degree):
    """The dissertation's terms: 1, x, y | x^2, xy, y^2 | x^2y, xy^2, x^3, y^3."""
    cols = [np.ones_like(u), u, v]
    if degree >= 2:
        cols += [u * u, u * v, v * v]
    if degree >= 3:
        cols += [u * u * v, u * v * v, u**3, v**3]
    return np.column_stack(cols)


def least_squares(x, y, pts, degree) -> HeightMap:
    cx, sx = (x[0] + x[-1]) / 2, max((x[-1] - x[0]) / 2, 1e-9)
    cy, sy = (y[0] + y[-1]) / 2, max((y[-1] - y[0]) / 2, 1e-9)
    A = poly_terms((pts[:, 0] - cx) / sx, (pts[:, 1] - cy) / sy, degree)
    coef = np.linalg.solve(A.T @ A, A.T @ pts[:, 2])  # the normal equations
    X, Y = np.meshgrid((x - cx) / sx, (y - cy) / sy)
    z = poly_terms(X.ravel(), Y.ravel(), degree) @ coef
    return HeightMap(x, y, z.reshape(X.shape))


def run_method(name, x, y, pts, levels=None, exposed=None) -> HeightMap:
    if name == "captured":
        return as_captured(x, y, levels, exposed)
    if name == "spline":
        return spline(x, y, pts)
    if name == "nearest":
        return nearest(x, y, pts)
    if name in ("lsq1", "lsq2", "lsq3"):
        return least_squares(x, y, pts, int(name[-1]))
    raise ValueError(f"unknown seed method {name!r}")
