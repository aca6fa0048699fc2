"""Camera calibration: intrinsics and distortion from chessboards, homography to the liquid plane.

1. A few images of a chessboard held at different angles give the camera
   matrix K and the lens distortion (OpenCV's calibrateCamera on corners found
   to sub-pixel precision).
2. One image of the same board lying on the liquid plane (floating, or placed
   on a plate at the liquid level) gives the homography from undistorted
   pixels to mm on that plane: its corners, undistorted as points, against
   their known positions in the object frame.

Where the board lies in the object frame is a setting, `BoardPose`: the inner
corner that is seen nearest the top-left of the image is at (x0, y0) mm; the
corners of a row run along `angle_deg` (0 = +x) and successive rows run a
quarter turn clockwise from that, seen from above (the camera's view is not
mirrored, so rows run down the image as they run down the top view).

Pure: images in, arrays out; the calibrate command does the files.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InkSliceError
from .camera import CameraModel, undistort_points


class CalibrationError(InkSliceError):
    """The calibration images cannot give a calibration (board not found, sizes differ...)."""


@dataclass(frozen=True)
class Board:
    cols: int  # inner corners along a row
    rows: int  # inner corners along a column
    square_mm: float

    @property
    def pattern(self):
        return (self.cols, self.rows)


@dataclass(frozen=True)
class BoardPose:
    x0: float = 0.0
    y0: float = 0.0
    angle_deg: float = 0.0


@dataclass
class Intrinsics:
    K: np.ndarray
    dist: np.ndarray
    rms_px: float  # reprojection error of the corners
    size: tuple  # (width, height)


def _gray(image):
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


def find_corners(image: np.ndarray, board: Board, where="image") -> np.ndarray:
    """(cols*rows, 2) sub-pixel inner corners, row by row, first one nearest the image's top-left."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise CalibrationError(where, "not an 8-bit image")
    gray = _gray(image)
    found, corners = cv2.findChessboardCornersSB(gray, board.pattern, flags=cv2.CALIB_CB_ACCURACY)
    if not found:
        found, corners = cv2.findChessboardCorners(
            gray, board.pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        if found:
            corners = cv2.cornerSubPix(
                gray,
                corners,
                (5, 5),
                (-1, -1),
                (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3),
            )
    if not found:
        raise CalibrationError(where, f"chessboard with {board.cols}x{board.rows} inner corners not found")
    c = corners.reshape(-1, 2).astype(np.float64)
    return _canonical_order(c, board)


def _canonical_order(c, board):
    """The detector may start from any corner and run either way: fix the order.

    Rows run a quarter turn clockwise from the row direction in the image
    (v down), and the first corner is the one nearest the image's top-left.
    """
    grid = c.reshape(board.rows, board.cols, 2)
    grids = [grid] + ([np.swapaxes(grid, 0, 1)] if board.rows == board.cols else [])
    candidates = [g[::sy, ::sx] for g in grids for sy in (1, -1) for sx in (1, -1)]

    def handed(g):
        a, b = g[0, -1] - g[0, 0], g[-1, 0] - g[0, 0]
        return a[0] * b[1] - a[1] * b[0] > 0

    best = min((g for g in candidates if handed(g)), key=lambda g: g[0, 0].sum())
    return np.ascontiguousarray(best).reshape(-1, 2)


def board_points(board: Board) -> np.ndarray:
    """Corner positions on the board (mm), z = 0, in the order find_corners returns."""
    j, i = np.mgrid[0 : board.rows, 0 : board.cols]
    return np.column_stack(
        [i.ravel() * board.square_mm, j.ravel() * board.square_mm, np.zeros(board.rows * board.cols)]
    ).astype(np.float64)


def intrinsics(images, board: Board, names=None) -> Intrinsics:
    """K and distortion from several views of the board (all the same size)."""
    names = list(names) if names is not None else [f"image {k + 1}" for k in range(len(images))]
    if len(images) < 3:
        raise CalibrationError(
            "calibration", f"need at least 3 board images for intrinsics, got {len(images)}"
        )
    size: tuple[int, int] | None = None
    img_pts, obj_pts = [], []
    for image, name in zip(images, names):
        s = (image.shape[1], image.shape[0])
        if size is None:
            size = s
        elif s != size:
            raise CalibrationError(
                name,
                f"is {s[0]}x{s[1]}, the first image is {size[0]}x{size[1]}: "
                "all calibration images must come from the same camera mode",
            )
        img_pts.append(find_corners(image, board, name).astype(np.float32).reshape(-1, 1, 2))
        obj_pts.append(board_points(board).astype(np.float32))
    # k3 stays 0: with a handful of views it only buys overfitting at the
    # corners of the field, where the waterline of a big part lies
    assert size is not None  # at least 3 images
    rms, K, dist = _calibrate_camera(obj_pts, img_pts, size)
    return Intrinsics(K, dist.ravel()[:5], float(rms), size)


def _calibrate_camera(obj_pts, img_pts, size):
    """cv2.calibrateCamera on one thread. Threaded, it sums in whatever order its threads
    finish: the same images gave K 1e-13 apart from run to run, and a bench that commissions
    afresh and then scans gave 0.0288 and 0.0290 mm of Ea. One thread makes commissioning
    repeatable. The setting is process-wide: the lock keeps two calibrations from restoring
    each other's."""
    with _ONE_THREAD:
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            rms, K, dist, _, _ = cv2.calibrateCamera(
                obj_pts, img_pts, size, None, None, flags=cv2.CALIB_FIX_K3
            )
        finally:
            cv2.setNumThreads(threads)
    return rms, K, dist


_ONE_THREAD = threading.Lock()


def plane_points(board: Board, pose: BoardPose) -> np.ndarray:
    """Where the corners lie on the liquid plane, in the object frame (mm)."""
    p = board_points(board)[:, :2]
    a = np.radians(pose.angle_deg)
    along = np.array([np.cos(a), np.sin(a)])
    down = np.array([np.sin(a), -np.cos(a)])  # a quarter turn clockwise seen from above
    return np.array([pose.x0, pose.y0]) + p[:, :1] * along + p[:, 1:] * down


def plane_homography(image, board: Board, pose: BoardPose, K=None, dist=None, where="plane image"):
    """Homography undistorted pixel -> object-frame mm on the liquid plane, and the camera height.

    Returns (H, height_mm, rms_mm); height_mm is None without K.
    """
    uv = undistort_points(find_corners(image, board, where), K, dist)
    xy = plane_points(board, pose)
    Hm, _ = cv2.findHomography(uv, xy, 0)
    if Hm is None:
        raise CalibrationError(where, "the board's corners do not give a homography")
    Hm = Hm / Hm[2, 2]
    h = np.column_stack([uv, np.ones(len(uv))]) @ Hm.T
    rms = float(np.sqrt(np.mean(np.sum((h[:, :2] / h[:, 2:] - xy) ** 2, axis=1))))
    height = None
    if K is not None:
        obj = np.column_stack([xy, np.zeros(len(xy))])
        ok, rvec, tvec = cv2.solvePnP(obj, uv.reshape(-1, 1, 2), K, None)
        if ok:
            R, _ = cv2.Rodrigues(rvec)
            height = float(abs((-R.T @ tvec).ravel()[2]))
    return Hm, height, rms


def camera_json(size, Hm, K=None, dist=None, height_mm=None) -> dict:
    """Exactly scan.json's "camera" block."""
    return CameraModel(int(size[0]), int(size[1]), Hm, K, dist, height_mm).to_json()


def calibrate(
    board_images, plane_image, board: Board, pose: BoardPose, board_names=None, plane_name="plane image"
) -> tuple[dict, dict]:
    """The whole calibration: (camera block, report figures)."""
    intr = intrinsics(board_images, board, board_names)
    size = (plane_image.shape[1], plane_image.shape[0])
    if size != intr.size:
        raise CalibrationError(
            plane_name, f"is {size[0]}x{size[1]}, the board images are {intr.size[0]}x{intr.size[1]}"
        )
    Hm, height, rms_mm = plane_homography(plane_image, board, pose, intr.K, intr.dist, plane_name)
    report = {"reprojection_rms_px": intr.rms_px, "plane_rms_mm": rms_mm, "images": len(board_images)}
    return camera_json(size, Hm, intr.K, intr.dist, height), report
