"""The camera model: where a pixel of a frame lies on the liquid plane, and back.

Everything that turns pixels into mm (or mm into pixels) asks this one model,
so the waterlines, the seed method's edge pixels, the live height map, the
meniscus' perspective and the level planner all see the same geometry.

The model is scan.json's "camera" block (docs/scan-format.md):

- `homography` maps an *undistorted* pixel (u, v, 1) to (x, y, 1) in mm on the
  liquid plane, in the object frame;
- `K` and `dist` are OpenCV's camera matrix and distortion coefficients; frames
  keep their lens distortion, and only the points found in them are undistorted
  (cheaper than remapping a whole frame, and it loses no sharpness);
- `height_mm` is the camera centre's height above the liquid plane, which the
  meniscus and wall corrections need for their perspective.

Reading and checking the block is camera_block.py's; scanfile.py holds the
file layout. Pixels here are (u, v) with u across, the centre of the top-left
pixel at (0, 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np


def undistort_points(uv, K, dist) -> np.ndarray:
    """Distorted pixel positions (N, 2) -> where a lens without distortion would show
    them, in pixels. Without K or dist the points are returned as they are."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    if K is None or dist is None or not len(uv):
        return uv
    return cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, P=K).reshape(-1, 2)


@dataclass
class CameraModel:
    width: int
    height: int
    homography: np.ndarray  # undistorted pixel (u, v, 1) -> liquid plane (x, y, 1), mm
    K: np.ndarray | None = None  # OpenCV camera matrix
    dist: np.ndarray | None = None  # OpenCV distortion coefficients
    height_mm: float | None = None  # camera centre above the liquid plane
    extra: dict = field(default_factory=dict)  # the block's other keys, written back unchanged

    def __post_init__(self):
        self.homography = np.asarray(self.homography, np.float64)
        if self.K is not None:
            self.K = np.asarray(self.K, np.float64)
        if self.dist is not None:
            self.dist = np.asarray(self.dist, np.float64).ravel()

    def to_json(self) -> dict:
        """Exactly scan.json's "camera" block."""
        out = dict(self.extra)
        out.update(width=int(self.width), height=int(self.height), homography=self.homography.tolist())
        if self.K is not None:
            out["K"] = self.K.tolist()
        if self.dist is not None:
            out["dist"] = self.dist.tolist()
        if self.height_mm is not None:
            out["height_mm"] = float(self.height_mm)
        return out

    # -- pixels and mm -------------------------------------------------------------

    def undistort(self, uv) -> np.ndarray:
        """Distorted pixels (as in the frame) -> undistorted pixels, (N, 2)."""
        return undistort_points(uv, self.K, self.dist)

    def distort(self, uv) -> np.ndarray:
        """Undistorted pixels -> where the frame shows them (the lens put back), (N, 2)."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        if self.K is None or self.dist is None:
            return uv
        K = self.K
        rays = np.column_stack(
            [(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(uv))]
        )
        proj, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, self.dist)
        return proj.reshape(-1, 2)

    def undistorted_to_mm(self, uv) -> np.ndarray:
        """Undistorted pixels -> (x, y) mm on the liquid plane (the homography alone)."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        H = self.homography
        h = uv @ H[:, :2].T + H[:, 2]
        return h[:, :2] / h[:, 2:3]

    def mm_to_undistorted(self, xy) -> np.ndarray:
        """(x, y) mm on the liquid plane -> undistorted pixels (non-finite where the plane
        point is on the camera's horizon)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        h = np.column_stack([xy, np.ones(len(xy))]) @ np.linalg.inv(self.homography).T
        with np.errstate(divide="ignore", invalid="ignore"):
            return h[:, :2] / h[:, 2:3]

    def pixels_to_mm(self, uv) -> np.ndarray:
        """Frame pixels (distorted, sub-pixel) -> (x, y) mm on the liquid plane, (N, 2)."""
        return self.undistorted_to_mm(self.undistort(uv))

    def mm_to_pixels(self, xy) -> np.ndarray:
        """(x, y) mm on the liquid plane -> frame pixels (where the camera sees them), (N, 2)."""
        return self.distort(self.mm_to_undistorted(xy))

    # -- what the geometry implies ----------------------------------------------------

    def pixel_mm(self) -> float:
        """The side of a pixel on the liquid plane at the frame's centre, mm (the square of
        equal area; the lens left out): how finely a waterline can be placed."""
        cx, cy = 0.5 * self.width, 0.5 * self.height
        xy = self.undistorted_to_mm([[cx, cy], [cx + 1, cy], [cx, cy + 1]])
        (ax, ay), (bx, by) = xy[1] - xy[0], xy[2] - xy[0]
        return float(np.sqrt(abs(ax * by - ay * bx)))

    def centre_xy(self) -> tuple[float, float] | None:
        """The camera centre over the base, (x, y) mm, from K and the homography; None
        without K. The perspective of what stands above the ink needs it."""
        if self.K is None:
            return None
        M = np.linalg.inv(self.K) @ np.linalg.inv(self.homography)
        M = M / np.linalg.norm(M[:, 0])  # ~ [r1 r2 t] of the plane in the camera
        r1, r2, t = M[:, 0], M[:, 1], M[:, 2]
        R = np.column_stack([r1, r2, np.cross(r1, r2)])
        C = -R.T @ t
        return float(C[0]), float(C[1])
