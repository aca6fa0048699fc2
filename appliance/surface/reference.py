"""Reference parts: shapes the box knows exactly, scanned to calibrate the meniscus and to
measure how well the box works ("this box measures the 25.4 mm ball to 0.02 mm").

A user can get one of them: a precision ball (bearing balls of 25.4 mm and other sizes
are ground to a few micrometres) lying on the base. Seen from above it is its upper
hemisphere standing on its equator's outline, so as a height map it is
    z = r + sqrt(r^2 - d^2)  inside the disc of radius r,
and where it lies on the base is found from the scan itself (locate_ball): the user
puts it down by hand.

fit_meniscus(scan, part, waterlines) is the whole calibration from a scan and its
waterlines (the caller extracts them, process.extract_waterlines: this room reads no
frames): the tank's displacement when scan.json has the tank (and the ink's fall under the
camera, when it says the ink falls), the camera's perspective, and
surface.meniscus.calibrate_meniscus. reference_error compares a height map of the
part with its true shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InkSliceError
from .meniscus import calibrate_meniscus

BALL_DIAMETER_MM = 25.4  # the default reference: a one-inch precision ball


@dataclass(frozen=True)
class Ball:
    """A ball of `diameter_mm` lying on the base, its centre over (cx, cy)."""

    diameter_mm: float = BALL_DIAMETER_MM
    cx: float = 50.0
    cy: float = 50.0

    @property
    def radius(self) -> float:
        return self.diameter_mm / 2.0

    @property
    def name(self) -> str:
        return f"{self.diameter_mm:g} mm ball"

    @property
    def bounds(self):
        r = self.radius
        return (self.cx - r, self.cx + r, self.cy - r, self.cy + r)

    def inside(self, x, y):
        return np.hypot(np.asarray(x, float) - self.cx, np.asarray(y, float) - self.cy) < self.radius

    def height(self, x, y):
        r = self.radius
        d2 = (np.asarray(x, float) - self.cx) ** 2 + (np.asarray(y, float) - self.cy) ** 2
        return np.where(d2 < r * r, r + np.sqrt(np.maximum(r * r - d2, 0.0)), 0.0)

    def at(self, cx, cy) -> Ball:
        return Ball(self.diameter_mm, float(cx), float(cy))

    def to_json(self) -> dict:
        return {
            "kind": "ball",
            "diameter_mm": self.diameter_mm,
            "centre_mm": [round(self.cx, 3), round(self.cy, 3)],
        }


def _circle_centre(P):
    """Least-squares circle through points (Kasa): its centre."""
    x, y = P[:, 0], P[:, 1]
    A = np.column_stack([2 * x, 2 * y, np.ones(len(x))])
    sol, *_ = np.linalg.lstsq(A, x * x + y * y, rcond=None)
    return sol[:2]


def locate_ball(waterlines, ball: Ball) -> Ball:
    """The ball where the scan sees it: the median centre of the waterlines' circles above
    its equator (a meniscus changes their radii, not their centres)."""
    centres = []
    for wl in waterlines:
        P = np.asarray(wl.points, float)
        if len(P) >= 12 and wl.level_mm > ball.radius + 0.5:
            centres.append(_circle_centre(P))
    if not centres:
        raise InkSliceError(
            "reference scan",
            f"no waterline of the {ball.name} above its equator: "
            "is the ball in view, and did the scan start above its top?",
        )
    c = np.median(np.array(centres), axis=0)
    return ball.at(c[0], c[1])


def fit_meniscus(scan, part, waterlines):
    """(MeniscusModel, the part where it was found) from a scan of a reference part and
    its waterlines.

    `part` is a Ball (located in the scan) or any known surface with bounds/inside/height
    at its true place."""
    if isinstance(part, Ball):
        part = locate_ball(waterlines, part)
    cam = scan.camera
    model = calibrate_meniscus(
        waterlines,
        part,
        tank_area_mm2=scan.tank_area_mm2,
        camera_xy_mm=cam.centre_xy(),
        camera_height_mm=cam.height_mm,
        ink_falls=scan.ink_falls,
    )
    return model, part


def reference_error(part, hm, margin_mm: float = 1.0) -> dict:
    """How far a height map of the reference part is from its true shape, on the part's top
    (cells more than `margin_mm` inside its outline): mean and largest absolute error, mm."""
    X, Y = hm.grid()
    z = np.asarray(hm.z, float)
    x0, x1, y0, y1 = part.bounds
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    r = min(x1 - x0, y1 - y0) / 2
    keep = np.isfinite(z) & (np.hypot(X - cx, Y - cy) < r - margin_mm) & part.inside(X, Y)
    if not keep.any():
        raise InkSliceError("reference scan", "the height map has no cell on the reference part's top")
    err = np.abs(z[keep] - part.height(X[keep], Y[keep]))
    return {
        "mean_abs_error_mm": round(float(err.mean()), 4),
        "max_error_mm": round(float(err.max()), 4),
        "cells": int(keep.sum()),
    }
