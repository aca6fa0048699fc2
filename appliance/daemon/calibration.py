"""Guided calibration of the camera's view of the liquid plane, step by step from the web UI.

    home    open the bench, home the stage (the base empty)
    target  raise the base to the ink line: the chessboard laid on it lies on the liquid plane
    detect  light on, one frame, find the board (vision.calibration.plane_homography);
            the preview with the corners drawn becomes the live frame
    accept  store the camera block (scan.json's "camera") as the newest calibration;
            the next scan uses it (runner._calibrated_camera)

The lens (K, distortion) is not found here: it needs several tilted views
(`inkslice calibrate`). When a stored calibration has them they are kept and
the board's corners are undistorted with them; the plane homography is what
the guided steps renew (the camera was bumped, the bench moved).

The board lies centred on the base at the jig position (JIG), the same as in
commissioning's camera step, so both give the same base coordinates. What
must be on the base is asked through the panel's Operator (hw/base.py): on a
real box a message, on the simulated bench the board is placed and the
virtual camera shows it.

The bench's devices stay open from `home` to `accept`, and the service
refuses scans meanwhile; so every step can be cancelled ("cancel", also while
a step runs: interrupt() stops the stage, close() gives the devices back and
starts over at "home"). Steps must come in order; a failed step can be
retried or cancelled. Errors are SettingError (wrong step) or the device's
own error.
"""

from __future__ import annotations

import threading
import time

import cv2
import numpy as np

from ..errors import SettingError
from ..hw.base import Placement
from ..vision.calibration import Board, BoardPose, camera_json, find_corners, plane_homography
from ..vision.printboard import PRINTED

STEPS = (
    ("home", "Empty the base, then home the stage"),
    (
        "target",
        "Lay the printed chessboard flat on the base, centred, its rows along the base's x side; "
        "the stage raises it to the ink line",
    ),
    ("detect", "Capture a frame and find the board's corners"),
    ("accept", "Check the preview and accept the camera model"),
)
BOARD = PRINTED  # 9 x 6 inner corners, 10 mm squares (vision/printboard.py)
# the printed board lies centred on the base, its rows along x: its first inner corner
# (nearest the image's top-left) at (10, 75) mm, the squares' centre at the base's centre (50, 50)
JIG = BoardPose(10.0, 75.0, 0.0)
POSE = JIG


def board_details(board: Board = BOARD, pose: BoardPose = JIG) -> dict:
    """The board and where it lies, as a Placement's details (what the simulated bench renders)."""
    return {
        "inner_corners": [board.cols, board.rows],
        "square_mm": board.square_mm,
        "first_corner_mm": [pose.x0, pose.y0],
        "angle_deg": pose.angle_deg,
    }


class GuidedCalibration:
    def __init__(
        self,
        open_devices,
        store,
        settings,
        show_frame,
        board: Board = BOARD,
        pose: BoardPose = POSE,
        operator=None,
    ):
        self.open_devices, self.store, self.settings = open_devices, store, settings
        self.show_frame, self.board, self.pose, self.operator = show_frame, board, pose, operator
        self.step = 0
        self.detected = None
        self._camera = None
        self.devices = None
        self.lock = threading.Lock()

    @property
    def active(self) -> bool:
        return self.devices is not None

    def describe(self) -> dict:
        return {
            "steps": [{"id": s, "text": t} for s, t in STEPS],
            "step": self.step,
            "detected": dict(self.detected) if self.detected else None,
            "holds_bench": self.active,
        }

    def do(self, step: str) -> dict:
        ids = [s for s, _ in STEPS]
        if step not in ids:
            raise SettingError("step", f"unknown calibration step {step!r}; the steps are {', '.join(ids)}")
        want = ids[self.step]
        if step != want:
            raise SettingError("step", f"do step {want!r} first")
        getattr(self, "_" + step)()
        if step != "accept":  # accept closes the bench and starts over at "home"
            self.step += 1
        return self.describe()

    def interrupt(self):
        """Stop the stage at once (from another thread): a running home or move ends with an error."""
        devices = self.devices
        if devices is not None and devices.stage is not None:
            try:
                devices.stage.stop()
            except Exception:
                pass  # close() follows; the next step homes again

    def close(self):
        devices, self.devices = self.devices, None
        if devices is not None:
            devices.release()
            self._ask("clear", "Calibration over: take the board off the base")
        self.step, self.detected, self._camera = 0, None, None

    def _ask(self, kind, text, **details):
        if self.operator is not None:
            self.operator.place(Placement(kind, text, details))

    # -- the steps ---------------------------------------------------------------
    def _home(self):
        self.close()
        self._ask("empty", STEPS[0][1])
        self.devices = self.open_devices()
        try:
            self.devices.stage.home()
        except BaseException:
            self.close()
            raise

    def _target(self):
        # level 0 = the base's top at the ink line; the board's thickness (paper) is ignored
        self._ask("board_flat", STEPS[1][1], **board_details(self.board, self.pose))
        self.devices.stage.move_to(float(self.settings["level_at_home_mm"]))

    def _detect(self):
        frame = self.devices.capture_lit()
        lens = self._lens()
        K, dist = lens.get("K"), lens.get("dist")
        K = np.asarray(K, float) if K is not None else None
        dist = np.asarray(dist, float) if dist is not None else None
        Hm, height, rms_mm = plane_homography(frame, self.board, self.pose, K, dist, "calibration frame")
        h, w = frame.shape[:2]
        self._camera = camera_json(
            (w, h), Hm, K, dist, height if height is not None else lens.get("height_mm")
        )
        # mm per pixel at the image centre, for the operator's sanity check
        c = np.array([[w / 2, h / 2, 1], [w / 2 + 1, h / 2, 1]]) @ Hm.T
        c = c[:, :2] / c[:, 2:]
        self.detected = {
            "corners": self.board.cols * self.board.rows,
            "plane_rms_mm": round(rms_mm, 4),
            "mm_per_px": round(float(np.linalg.norm(c[1] - c[0])), 4),
            "lens": "from the stored calibration" if K is not None else "none (no lens model)",
        }
        self._preview(frame)

    def _accept(self):
        if self._camera is None:
            raise SettingError("step", "nothing detected to accept; do 'detect' again")
        self.store.add_calibration(
            {
                "camera": self._camera,
                "source": "guided",
                "report": dict(self.detected or {}),
                "accepted": time.time(),
            }
        )
        self.close()

    # -- helpers -------------------------------------------------------------------
    def _lens(self) -> dict:
        for cal in self.store.calibrations():
            cam = cal.get("camera") or {}
            if cam.get("K") is not None:
                return cam
        return {}

    def _preview(self, frame):
        show_board(self.show_frame, frame, self.board, find_corners(frame, self.board))


def show_board(show_frame, frame, board: Board, corners=None, what: str = "calibration") -> None:
    """The frame on the dashboard's preview, the board's corners drawn in when given."""
    img = frame if frame.ndim == 3 else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    if corners is not None:
        img = img.copy()
        cv2.drawChessboardCorners(img, board.pattern, corners.astype(np.float32).reshape(-1, 1, 2), True)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 80])
    if ok:
        show_frame(buf.tobytes(), {"level_mm": None, "time": time.time(), "what": what})
