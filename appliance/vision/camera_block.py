"""scan.json's "camera" block, read and checked: a CameraModel or one clear ScanError.

The camera must be a camera before anything is computed with it: an invertible
K, a lens the pipeline can undo (it undistorts points, camera.py), and a
homography that maps the whole frame onto the liquid plane, whatever its scale.
A hostile or broken block is refused here, never a traceback or a wrong part
later. scanfile.load_scan reads scan.json's block with it; the daemon reads its
stored calibration with it too.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import ScanError
from ..jsoncheck import matrix, optional_positive, short
from .camera import CameraModel

MAX_SIDE_PX = 20000
MAX_PIXELS = 100_000_000  # per frame
MAX_CAMERA_HEIGHT_MM = 10000.0
MAX_DIST_COEF = 1000.0  # lens distortion coefficients are of order 1
KNOWN = ("width", "height", "homography", "K", "dist", "height_mm")


def _check_homography(where, H, w, h):
    """The whole frame must map onto the liquid plane: judged on the matrix scaled to its
    largest entry (a homography and any multiple of it are the same mapping)."""
    top = float(np.max(np.abs(H)))
    if top == 0:
        raise ScanError(where, "camera.homography is all zeros")
    Hs = H / top
    corners = np.array([[-0.5, -0.5, 1], [w - 0.5, -0.5, 1], [w - 0.5, h - 0.5, 1], [-0.5, h - 0.5, 1]])
    p = corners @ Hs.T
    wz = p[:, 2]
    # the denominator is linear in (u, v): same sign at the corners = same sign on the whole frame
    if not (np.all(wz > 0) or np.all(wz < 0)) or np.min(np.abs(wz)) < 1e-3 * np.max(np.abs(wz)):
        raise ScanError(
            where,
            "camera.homography puts the liquid plane's horizon across (or at the edge "
            "of) the image: part of the frame would map to infinity or behind the camera",
        )
    quad = p[:, :2] / wz[:, None]
    edge = np.roll(quad, -1, axis=0) - quad
    nxt = np.roll(edge, -1, axis=0)
    cross = edge[:, 0] * nxt[:, 1] - edge[:, 1] * nxt[:, 0]
    lengths = np.hypot(edge[:, 0], edge[:, 1]) * np.hypot(nxt[:, 0], nxt[:, 1])
    if (
        not np.all(np.isfinite(quad))
        or np.any(np.abs(cross) <= 1e-9 * lengths)
        or not (np.all(cross > 0) or np.all(cross < 0))
    ):
        raise ScanError(where, "camera.homography is singular: it maps the frame onto a line or a point")
    area = 0.5 * abs(
        float(np.sum(quad[:, 0] * np.roll(quad[:, 1], -1) - np.roll(quad[:, 0], -1) * quad[:, 1]))
    )
    mm_per_px = math.sqrt(area / (w * h))
    if not 1e-4 <= mm_per_px <= 100:
        raise ScanError(
            where,
            f"camera.homography gives {mm_per_px:.3g} mm per pixel; a camera over a "
            "bench box sees between 0.0001 and 100 mm per pixel",
        )


def _check_K(where, K, w, h):
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (fx > 0 and fy > 0):
        raise ScanError(
            where,
            f"camera.K must have focal lengths fx, fy > 0 (it is not invertible "
            f"otherwise), got fx = {fx:g}, fy = {fy:g}",
        )
    if np.max(np.abs(K[2] - (0, 0, 1))) > 1e-9 or abs(K[1, 0]) > 1e-9:
        raise ScanError(where, "camera.K must have the form [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
    side = max(w, h)
    for name, f in (("fx", fx), ("fy", fy)):
        if not 0.05 * side <= f <= 1000 * side:
            raise ScanError(
                where,
                f"camera.K's {name} = {f:g} px is no lens for a {w}x{h} image "
                f"(expected {0.05 * side:g}..{1000 * side:g} px)",
            )
    if not (-0.5 * w <= cx <= 1.5 * w and -0.5 * h <= cy <= 1.5 * h):
        raise ScanError(
            where, f"camera.K's principal point ({cx:g}, {cy:g}) is far outside the {w}x{h} image"
        )
    if abs(K[0, 1]) > fx:
        raise ScanError(where, f"camera.K's skew {K[0, 1]:g} is larger than its focal length")


def _border_points(w, h, n=9):
    t = np.linspace(0, 1, n)
    u, v = t * (w - 1), t * (h - 1)
    pts = np.concatenate(
        [
            np.column_stack([u, np.zeros(n)]),
            np.column_stack([u, np.full(n, h - 1.0)]),
            np.column_stack([np.zeros(n), v]),
            np.column_stack([np.full(n, w - 1.0), v]),
            np.column_stack([u, v]),
        ]
    )
    return pts.reshape(-1, 1, 2)


def _check_distortion(where, K, dist, w, h):
    """The pipeline undistorts waterline points (cv2.undistortPoints): the lens model must be
    one that this undoes, across the whole frame, to well under a pixel."""
    biggest = float(np.max(np.abs(dist)))
    if biggest > MAX_DIST_COEF:
        raise ScanError(
            where,
            f"camera.dist has a coefficient of {biggest:g}: lens distortion coefficients "
            f"are of order 1 (at most {MAX_DIST_COEF:g})",
        )
    pts = _border_points(w, h)
    with np.errstate(all="ignore"):
        norm = cv2.undistortPoints(pts, K, dist)
        ok = np.all(np.isfinite(norm))
        if ok:
            rays = np.concatenate([norm.reshape(-1, 2), np.ones((len(pts), 1))], axis=1)
            back, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, dist)
            miss = float(np.max(np.hypot(*(back.reshape(-1, 2) - pts.reshape(-1, 2)).T)))
            ok = math.isfinite(miss) and miss <= 0.5
    if not ok:
        raise ScanError(
            where,
            "camera.dist is not a lens that can be undone over the frame (undistorting "
            "its border and distorting it back misses by more than half a pixel)",
        )


def read_camera(where, cam) -> CameraModel:
    """The CameraModel of a camera block (a dict), checked; `where` names it in errors."""
    if not isinstance(cam, dict):
        raise ScanError(where, "'camera' must be an object")
    for key in ("width", "height", "homography"):
        if key not in cam:
            raise ScanError(where, f"camera.{key} is missing")
    w, h = cam["width"], cam["height"]
    if not (type(w) is int and type(h) is int and w > 0 and h > 0):
        raise ScanError(where, f"camera.width/height must be positive integers, got {short(w)} x {short(h)}")
    if w > MAX_SIDE_PX or h > MAX_SIDE_PX or w * h > MAX_PIXELS:
        raise ScanError(
            where,
            f"camera.width/height of {short(w)} x {short(h)} pixels is more than a frame may "
            f"have ({MAX_SIDE_PX} a side, {MAX_PIXELS // 1_000_000} megapixels)",
        )
    H = matrix(where, cam["homography"], "camera.homography", (3, 3))
    _check_homography(where, H, w, h)
    K = matrix(where, cam["K"], "camera.K", (3, 3)) if cam.get("K") is not None else None
    if K is not None:
        _check_K(where, K, w, h)
    dist = None
    if cam.get("dist") is not None:
        try:
            dist = np.asarray(cam["dist"], dtype=float).ravel()
        except (TypeError, ValueError, OverflowError):
            dist = np.zeros(0)
        if dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
            raise ScanError(where, "camera.dist must be 4, 5, 8, 12 or 14 finite numbers")
        if K is not None:
            _check_distortion(where, K, dist, w, h)
    hmm = optional_positive(
        where,
        cam,
        "height_mm",
        "camera.height_mm",
        MAX_CAMERA_HEIGHT_MM,
        f"the camera must be above the liquid (0 < height <= {MAX_CAMERA_HEIGHT_MM:g} mm)",
    )
    return CameraModel(w, h, H, K, dist, hmm, {k: v for k, v in cam.items() if k not in KNOWN})
