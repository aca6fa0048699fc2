"""The height map so far, for the dashboard while a scan runs.

Levels run from the top down, so the first level at which a point of the
plane is seen standing out of the ink is (to within one step) its height. A
coarse regular grid in mm over the camera's field (the image corners mapped
through the camera model's homography) is looked up in each frame's part mask
(vision/part.py, the mask the level planner already has) and every cell seen
for the first time gets that level.

A preview, not the result: the lens distortion is ignored and the mask is
coarse; processing builds the real height map.
Shape of to_json(), as the web's live view expects:
    {"x": [mm...], "y": [mm...], "z": [[mm or None, ...] per y]}
"""

from __future__ import annotations

import numpy as np

from ..vision.camera import CameraModel

CELLS = 40


class LiveMap:
    def __init__(self, camera: CameraModel, n: int = CELLS):
        w, h = camera.width, camera.height
        xy = camera.undistorted_to_mm([[0, 0], [w, 0], [0, h], [w, h]])
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
        self.xs = x0 + (np.arange(n) + 0.5) * (x1 - x0) / n
        self.ys = y0 + (np.arange(n) + 0.5) * (y1 - y0) / n
        X, Y = np.meshgrid(self.xs, self.ys)
        uv = camera.mm_to_undistorted(np.column_stack([X.ravel(), Y.ravel()])).reshape(n, n, 2)
        self.u = uv[..., 0] / w  # 0..1 across the image
        self.v = uv[..., 1] / h
        self.inside = (
            np.isfinite(self.u)
            & np.isfinite(self.v)
            & (self.u >= 0)
            & (self.u < 1)
            & (self.v >= 0)
            & (self.v < 1)
        )
        self.u = np.where(self.inside, self.u, 0.0)
        self.v = np.where(self.inside, self.v, 0.0)
        self.z = np.full((n, n), np.nan)

    def add(self, mask: np.ndarray, level_mm: float) -> None:
        """`mask`: where the part stands out of the ink in the frame at `level_mm` (find_part's)."""
        mh, mw = mask.shape
        r = np.clip((self.v * mh).astype(int, copy=False), 0, mh - 1)
        c = np.clip((self.u * mw).astype(int, copy=False), 0, mw - 1)
        seen = np.zeros_like(self.inside)
        seen[self.inside] = mask[r[self.inside], c[self.inside]]
        new = seen & np.isnan(self.z)
        self.z[new] = float(level_mm)

    def to_json(self) -> dict:
        z = [[None if not np.isfinite(v) else round(float(v), 3) for v in row] for row in self.z]
        return {
            "x": [round(float(v), 3) for v in self.xs],
            "y": [round(float(v), 3) for v in self.ys],
            "z": z,
        }
