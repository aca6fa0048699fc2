"""Calibration images of the virtual bench: a chessboard seen through the rig's lens.

Two kinds of image, as a user would take them on the real bench:
- poses: the board held at several heights and tilts under the camera, for
  cv2.calibrateCamera (K and the lens distortion);
- plane: the board floating flat ON the liquid, at a known place in the object
  frame (it lies in the tank's corner jig), for the pixel -> liquid-plane
  homography of scan.json.

Default board: 9 x 6 inner corners, 8 mm squares (80 x 56 mm of squares on a
96 x 72 mm white card): small enough to stay whole in the frame when tilted
30 degrees 60 mm above the liquid, big enough to fill half of it. 9 x 6 is not
symmetric under a half turn only by its colours, so the board's first corner
is where its (0, 0) square - black - sits.

The images are rendered like frames: every pixel's true ray (through the
distortion) meets the card's plane; the checker is anti-aliased analytically
(an exact box filter of the pixel's footprint on the card), then blur and noise.

render_calibration(folder) writes the images and board.json (what the user
knows: the board and where the flat one lies) into `folder`, and the truth -
the rig's true camera model, every pose, every corner's true pixel - to
`<folder>.truth.json` outside it, like a scan's truth.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .. import atomicio
from ..scanfile import write_frame
from .effects import Effects, camera_effects
from .rig import Rig, _rot_x, _rot_y, _rot_z, pixel_map


@dataclass(frozen=True)
class Board:
    cols: int = 9  # inner corners along the board's x
    rows: int = 6  # inner corners along the board's y
    square_mm: float = 8.0
    margin_squares: float = 1.0  # white card around the squares
    white: float = 232.0
    black: float = 22.0

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame (mm, z = 0), row by row (OpenCV order)."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        return np.column_stack([i.ravel() * self.square_mm, j.ravel() * self.square_mm, np.zeros(i.size)])

    @property
    def squares_box(self):
        s = self.square_mm
        return (-s, self.cols * s, -s, self.rows * s)

    @property
    def card_box(self):
        x0, x1, y0, y1 = self.squares_box
        m = self.margin_squares * self.square_mm
        return (x0 - m, x1 + m, y0 - m, y1 + m)


@dataclass(frozen=True)
class Pose:
    """Board frame -> plane frame (x, y on the liquid plane, z up from it)."""

    rx_deg: float
    ry_deg: float
    rz_deg: float
    x_mm: float  # where the board's centre is
    y_mm: float
    z_mm: float  # height above the liquid

    def rotation(self):
        return (
            _rot_z(math.radians(self.rz_deg))
            @ _rot_y(math.radians(self.ry_deg))
            @ _rot_x(math.radians(self.rx_deg))
        )


DEFAULT_POSES = (
    Pose(0, 0, 0, 50, 50, 40),
    Pose(28, 0, 4, 48, 52, 35),
    Pose(-28, 0, -4, 52, 48, 35),
    Pose(0, 28, 8, 50, 50, 35),
    Pose(0, -28, -8, 50, 50, 35),
    Pose(20, 20, 15, 45, 55, 25),
    Pose(-20, 20, -15, 55, 45, 25),
    Pose(20, -20, 25, 50, 50, 25),
    Pose(-20, -20, -25, 50, 50, 25),
    Pose(12, -8, 40, 30, 38, 10),
    Pose(-10, 12, -35, 70, 62, 10),
    Pose(15, 15, 90, 50, 50, 55),
)


def _box_cells(b, w, s, lo_cell, hi_cell):
    """Box filter (width w < s) of the 1-D indicators 'cell index even' and 'odd',
    restricted to cells lo_cell..hi_cell. Exact: the window overlaps two cells."""
    left = b - w / 2
    c0 = np.floor(left / s)
    f0 = np.clip(((c0 + 1) * s - left) / w, 0.0, 1.0)  # share of the window in cell c0
    f1 = 1.0 - f0
    c1 = c0 + 1
    in0 = (c0 >= lo_cell) & (c0 <= hi_cell)
    in1 = (c1 >= lo_cell) & (c1 <= hi_cell)
    even0 = np.mod(c0, 2) == 0
    even = f0 * (in0 & even0) + f1 * (in1 & ~even0)
    odd = f0 * (in0 & ~even0) + f1 * (in1 & even0)
    return even, odd


def _checker(bx, by, w, board: Board):
    """Black coverage of the squares and coverage of the card at board points,
    box-filtered over the pixel's footprint w (mm) on the card.

    Square (i, j) (i, j from -1: the corner squares) is black when i + j is even.
    The indicator is separable, (even_x even_y + odd_x odd_y), and so is the box
    filter: the product of 1-D box filters is exact."""
    s = board.square_mm
    w = np.minimum(w, 0.9 * s)
    ex, ox = _box_cells(bx, w, s, -1, board.cols - 1)
    ey, oy = _box_cells(by, w, s, -1, board.rows - 1)
    black = ex * ey + ox * oy
    x0, x1, y0, y1 = board.card_box
    cx = np.clip((np.minimum(bx + w / 2, x1) - np.maximum(bx - w / 2, x0)) / w, 0.0, 1.0)
    cy = np.clip((np.minimum(by + w / 2, y1) - np.maximum(by - w / 2, y0)) / w, 0.0, 1.0)
    card = cx * cy
    return black, card


def render_board(board: Board, pose: Pose, rig: Rig = None, effects: Effects = None, rng=None):
    """One 8-bit BGR image of the board at `pose`, through the rig's (distorted) lens."""
    rig = rig or Rig()
    effects = effects or Effects(blur_sigma_px=0.6, noise_sigma=1.5, lens_distortion=True)
    rng = rng if rng is not None else np.random.default_rng(0)
    pm = pixel_map(rig, effects.lens_distortion)
    C = rig.centre
    R = pose.rotation()
    t = np.array([pose.x_mm, pose.y_mm, pose.z_mm])
    # the board's centre (of its squares) is placed at t
    x0, x1, y0, y1 = board.squares_box
    centre_b = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    origin = t - R @ centre_b
    n = R[:, 2]
    # rays: from C through the pixel's liquid-plane point
    dx = pm.x0.astype(np.float64) - C[0]
    dy = pm.y0.astype(np.float64) - C[1]
    dz = -C[2]
    denom = n[0] * dx + n[1] * dy + n[2] * dz
    s = (n @ (origin - C)) / denom
    X = C[0] + s * dx - origin[0]
    Y = C[1] + s * dy - origin[1]
    Z = C[2] + s * dz - origin[2]
    bx = R[0, 0] * X + R[1, 0] * Y + R[2, 0] * Z
    by = R[0, 1] * X + R[1, 1] * Y + R[2, 1] * Z
    # pixel footprint on the card (mm): the ramp half-width
    gu = np.hypot(np.gradient(bx, axis=1), np.gradient(by, axis=1))
    gv = np.hypot(np.gradient(bx, axis=0), np.gradient(by, axis=0))
    w = np.maximum(np.maximum(gu, gv), 1e-6)
    black, a_card = _checker(bx, by, w, board)
    # black is part of the card: its colour over the card's area is white except there
    grey = board.white - (board.white - board.black) * np.where(
        a_card > 1e-6, black / np.maximum(a_card, 1e-6), 0.0
    )
    # light falls on the card at an angle: a matte card is Lambertian
    lam = 0.55 + 0.45 * abs(float(n @ rig.light_unit()))
    card = (grey * lam).astype(np.float32)
    ink = np.asarray(rig.ink_bgr, np.float32)
    a = a_card.astype(np.float32)[..., None]
    img = (1 - a) * ink + a * card[..., None] * np.array([1.0, 1.0, 0.98], np.float32)
    return camera_effects(img.astype(np.float32), rig, effects, pm, rng)


def true_corners(board: Board, pose: Pose, rig: Rig, distorted=True) -> np.ndarray:
    """The inner corners' true pixel positions (OpenCV order), through the lens."""
    R = pose.rotation()
    x0, x1, y0, y1 = board.squares_box
    centre_b = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    origin = np.array([pose.x_mm, pose.y_mm, pose.z_mm]) - R @ centre_b
    pts = board.object_points() @ R.T + origin
    return rig.project(pts, distorted=distorted)


def plane_pose(x_mm=50.0, y_mm=50.0, rz_deg=0.0) -> Pose:
    """The board floating flat on the liquid, its squares centred at (x, y)."""
    return Pose(0.0, 0.0, rz_deg, x_mm, y_mm, 0.0)


def _vision_board_pose(board: Board, plane: Pose, plane_xy, rig: Rig) -> dict:
    """The flat board's place in the vision team's BoardPose terms."""
    uv = rig.project(np.column_stack([plane_xy, np.zeros(len(plane_xy))]), distorted=True)
    first = int(np.argmin(np.hypot(uv[:, 0], uv[:, 1])))
    x0, y0 = plane_xy[first]
    # the row through that corner, in the direction that runs right in the image
    i = first % board.cols
    nb = first + 1 if i + 1 < board.cols else first - 1
    d = plane_xy[nb] - plane_xy[first]
    if uv[nb, 0] < uv[first, 0]:
        d = -d
    return {"x0": float(x0), "y0": float(y0), "angle_deg": float(np.degrees(np.arctan2(d[1], d[0])))}


def render_calibration(
    folder,
    rig: Rig = None,
    board: Board = None,
    poses=DEFAULT_POSES,
    plane: Pose = None,
    effects: Effects = None,
    seed: int = 0,
) -> dict:
    """Render pose_NN.png and plane.png into `folder`, board.json beside them, and
    the truth (camera model, poses, corner pixels) to `<folder>.truth.json`.

    Returns the truth as a dict (with the true CameraModel under "camera_model").
    """
    rig = rig or Rig()
    board = board or Board()
    plane = plane or plane_pose(rig.camera_x_mm, rig.camera_y_mm)
    effects = effects or Effects(blur_sigma_px=0.6, noise_sigma=1.5, lens_distortion=True)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    images = []
    for i, pose in enumerate(list(poses) + [plane]):
        is_plane = i == len(poses)
        name = "plane.png" if is_plane else f"pose_{i + 1:02d}.png"
        corners = true_corners(board, pose, rig)
        margin = 10
        if (
            corners.min() < margin
            or corners[:, 0].max() > rig.width - margin
            or corners[:, 1].max() > rig.height - margin
        ):
            raise ValueError(f"{name}: the board leaves the frame at pose {pose}")
        img = render_board(board, pose, rig, effects, np.random.default_rng([seed, i]))
        write_frame(folder, name, img)
        images.append(
            {
                "file": name,
                "kind": "plane" if is_plane else "pose",
                "pose": asdict(pose),
                "corners_px": corners.tolist(),
            }
        )
    R = plane.rotation()
    x0, x1, y0, y1 = board.squares_box
    origin = np.array([plane.x_mm, plane.y_mm, 0.0]) - R @ np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    plane_xy = (board.object_points() @ R.T + origin)[:, :2]
    doc = {
        "format": "inkslice.calibration/1",
        "board": {
            "inner_corners": [board.cols, board.rows],
            "square_mm": board.square_mm,
            "first_square": "black",
            "object_points_mm": board.object_points()[:, :2].tolist(),
        },
        "images": [{"file": im["file"], "kind": im["kind"]} for im in images],
        "plane": {
            "file": "plane.png",
            "note": "board floating flat on the liquid; corners in the object frame, OpenCV order",
            "corners_xy_mm": plane_xy.tolist(),
            # appliance.vision.calibration.BoardPose: the inner corner seen nearest
            # the image's top-left, and the direction its row runs (0 = +x)
            "board_pose": _vision_board_pose(board, plane, plane_xy, rig),
        },
    }
    atomicio.write_json(folder / "board.json", doc)
    cm = rig.camera_model(distorted=effects.lens_distortion)
    truth = {
        "format": "inkslice.calibration-truth/1",
        "camera": cm.to_json(),
        "rig": rig.to_json(),
        "effects": effects.to_json(),
        "images": images,
    }
    atomicio.write_json(folder.parent / (folder.name + ".truth.json"), truth)
    truth["camera_model"] = cm
    return truth
