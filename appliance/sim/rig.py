"""The virtual bench's geometry: a pinhole camera fixed above the liquid plane.

Frames of reference
- Object frame: x right, y away from the viewer (up in a top view), z up from the
  base top. The liquid plane at level L is z = L.
- Plane frame: the same x, y; z measured from the liquid plane. The camera and
  the liquid plane are both fixed to the tank (the base moves, not the ink), so
  in the plane frame the camera never moves and one homography serves every
  frame. A point of the part at object height z is at plane height z - L.
- Camera frame (OpenCV): x right in the image, y down in the image, z along the
  optical axis. Looking straight down, camera x = world x, camera y = world -y,
  camera z = world -z: R0 = diag(1, -1, -1), a proper rotation (the top view is
  not mirrored). A small tilt is applied on top of it so the homography is not
  a pure scale, as on a real stand.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import numpy as np

from ..vision.camera import CameraModel


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], float)


def _rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], float)


def _rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], float)


@dataclass(frozen=True)
class Rig:
    """Everything fixed on the bench: camera, lens, light, ink, tank.

    Defaults: f = 3800 px at 300 mm gives ~0.079 mm/px on the liquid plane, a
    field of ~162 x 121 mm: a 100 x 100 mm part with margin, and still inside
    the frame when 50 mm of it stands above the liquid (it then appears 1.2x
    larger). The camera is a little off the base centre and tilted by under a
    degree, as a hand-set stand would be.
    """

    width: int = 2048
    height: int = 1536
    focal_px: float = 3800.0
    principal_u: float = 1030.0  # pixels; a few px off the image centre
    principal_v: float = 763.5
    camera_x_mm: float = 50.6  # camera centre over the base (object x, y)
    camera_y_mm: float = 49.3
    height_mm: float = 300.0  # camera centre above the liquid plane
    tilt_x_deg: float = 0.6  # rotations of the camera about its own axes
    tilt_y_deg: float = -0.4
    yaw_deg: float = 0.7
    dist: tuple = (-0.06, 0.04, 2.0e-4, -1.5e-4, 0.0)  # OpenCV k1 k2 p1 p2 k3
    light_dir: tuple = (-0.35, 0.45, 0.82)  # towards the lamp, object frame
    ambient: float = 0.38
    diffuse: float = 0.62
    part_bgr: tuple = (214.0, 220.0, 224.0)  # light grey part, fully lit
    ink_bgr: tuple = (62.0, 24.0, 10.0)  # opaque dark-blue ink (B, G, R)
    tank_area_mm2: float = 22500.0  # inner area of the tank (150 x 150 mm)

    # -- the camera -----------------------------------------------------------

    @property
    def centre(self) -> np.ndarray:
        """Camera centre in the plane frame (z = height above the liquid)."""
        return np.array([self.camera_x_mm, self.camera_y_mm, self.height_mm], float)

    def rotation(self) -> np.ndarray:
        """World (plane frame) -> camera rotation."""
        r0 = np.diag([1.0, -1.0, -1.0])
        tilt = (
            _rot_z(math.radians(self.yaw_deg))
            @ _rot_y(math.radians(self.tilt_y_deg))
            @ _rot_x(math.radians(self.tilt_x_deg))
        )
        return tilt @ r0

    def K(self) -> np.ndarray:
        return np.array(
            [[self.focal_px, 0, self.principal_u], [0, self.focal_px, self.principal_v], [0, 0, 1]], float
        )

    def dist_coeffs(self) -> np.ndarray:
        return np.asarray(self.dist, float)

    def plane_to_pixel(self) -> np.ndarray:
        """Homography: liquid plane (x, y, 1) in mm -> undistorted pixel."""
        R = self.rotation()
        t = -R @ self.centre
        M = self.K() @ np.column_stack([R[:, 0], R[:, 1], t])
        return M / M[2, 2]

    def homography(self) -> np.ndarray:
        """Undistorted pixel (u, v, 1) -> liquid plane (x, y, 1) in mm (scan.json)."""
        Hm = np.linalg.inv(self.plane_to_pixel())
        return Hm / Hm[2, 2]

    def camera_model(self, distorted: bool = True) -> CameraModel:
        """The TRUE camera model, as a perfect calibration would find it.

        `distorted` says whether the frames carry the lens distortion; when not,
        dist is written as zeros so processing leaves them alone.
        """
        dist = self.dist_coeffs() if distorted else np.zeros(5)
        return CameraModel(self.width, self.height, self.homography(), self.K(), dist, float(self.height_mm))

    def project(self, xyz_plane, distorted: bool = False) -> np.ndarray:
        """Pinhole projection of points in the plane frame (z above the liquid) to pixels."""
        p = np.atleast_2d(np.asarray(xyz_plane, float))
        R = self.rotation()
        pc = (p - self.centre) @ R.T
        x, y = pc[:, 0] / pc[:, 2], pc[:, 1] / pc[:, 2]
        if distorted:
            x, y = _distort(x, y, self.dist_coeffs())
        return np.column_stack([self.focal_px * x + self.principal_u, self.focal_px * y + self.principal_v])

    def project_object(self, xyz_object, level_mm: float, distorted: bool = False):
        """Projection of object-frame points when the liquid is at `level_mm`."""
        p = np.atleast_2d(np.asarray(xyz_object, float)).copy()
        p[:, 2] -= level_mm
        return self.project(p, distorted)

    def pixels_to_plane(self, uv, distorted: bool = False) -> np.ndarray:
        """Pixels -> the liquid-plane points (mm) their rays pass through."""
        uv = np.atleast_2d(np.asarray(uv, float))
        x = (uv[:, 0] - self.principal_u) / self.focal_px
        y = (uv[:, 1] - self.principal_v) / self.focal_px
        if distorted:
            x, y = _undistort(x, y, self.dist_coeffs())
        return _rays_to_plane(self, x, y)

    def light_unit(self) -> np.ndarray:
        v = np.asarray(self.light_dir, float)
        return v / np.linalg.norm(v)

    def to_json(self) -> dict:
        d = asdict(self)
        d["dist"] = list(self.dist)
        d["light_dir"] = list(self.light_dir)
        d["part_bgr"] = list(self.part_bgr)
        d["ink_bgr"] = list(self.ink_bgr)
        return d

    @classmethod
    def from_json(cls, d: dict) -> Rig:
        fields = {
            k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in cls.__dataclass_fields__
        }
        return cls(**fields)


# -- lens model (OpenCV's 5-coefficient Brown-Conrady) --------------------------


def _distort(x, y, dist):
    k1, k2, p1, p2, k3 = (list(dist) + [0.0] * 5)[:5]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


def _undistort(xd, yd, dist, iterations=8):
    """Invert _distort by OpenCV's fixed point. Each step shrinks the error ~50x for
    our lenses (|d distortion / dx| ~ 0.02 at the frame corners): 8 steps reach ~1e-13."""
    k1, k2, p1, p2, k3 = (list(dist) + [0.0] * 5)[:5]
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x = (xd - dx) / radial
        y = (yd - dy) / radial
    return x, y


def _rays_to_plane(rig: Rig, xn, yn):
    """Normalised camera coordinates -> intersection of the ray with the liquid plane."""
    R = rig.rotation()
    d = np.stack([xn, yn, np.ones_like(xn)], axis=-1) @ R  # R^T d, row-wise
    C = rig.centre
    s = -C[2] / d[..., 2]
    return np.stack([C[0] + s * d[..., 0], C[1] + s * d[..., 1]], axis=-1)


@dataclass
class PixelMap:
    """Per-pixel liquid-plane geometry of a rig, computed once and cached.

    x0, y0: where each pixel's ray meets the liquid plane (mm, float32);
    pix: the local size of a pixel on the plane (mm), which sets the width of
    the anti-aliasing ramp; kx, ky: horizontal travel of the ray per mm of
    height, (C - P0) / H, used by the perspective ray march.
    """

    x0: np.ndarray
    y0: np.ndarray
    pix: np.ndarray
    kx: np.ndarray
    ky: np.ndarray
    vignette_r2: np.ndarray  # squared distance from the image centre / half-diagonal^2


@functools.lru_cache(maxsize=2)  # ~75 MB each at 2048 x 1536
def pixel_map(rig: Rig, distorted: bool) -> PixelMap:
    v, u = np.mgrid[0 : rig.height, 0 : rig.width].astype(np.float64)
    x = (u - rig.principal_u) / rig.focal_px
    y = (v - rig.principal_v) / rig.focal_px
    if distorted:
        x, y = _undistort(x, y, rig.dist_coeffs())
    P = _rays_to_plane(rig, x, y)
    x0, y0 = P[..., 0], P[..., 1]
    gxu, gxv = np.gradient(x0)
    gyu, gyv = np.gradient(y0)
    # geometric mean of the two pixel edges' lengths on the plane
    pix = np.sqrt(np.hypot(gxv, gyv) * np.hypot(gxu, gyu))
    C = rig.centre
    kx = (C[0] - x0) / C[2]
    ky = (C[1] - y0) / C[2]
    cu, cv = (rig.width - 1) / 2, (rig.height - 1) / 2
    r2 = ((u - cu) ** 2 + (v - cv) ** 2) / (cu * cu + cv * cv)
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)
    return PixelMap(f32(x0), f32(y0), f32(pix), f32(kx), f32(ky), f32(r2))
