"""The real camera: a UVC webcam through OpenCV's V4L2 backend.

Everything automatic is switched off and locked for the whole scan: a frame's
brightness must change only because the waterline moved, never because the
camera re-metered (auto exposure would brighten the frame as the dark ink
covers more of it and shift the threshold). The resolution is fixed and
checked: a camera that silently falls back to 640 x 480 would make the scan's
homography wrong.

Stale frames: V4L2 queues buffers; after a move the first frames in the queue
show the part before (or during) the move. capture() grabs and drops
`flush` frames before retrieving the one it returns.

Select the device by a stable path: /dev/v4l/by-id/usb-...-video-index0 (or
the /dev/inkslice-camera symlink our udev rule makes), never /dev/videoN,
whose number changes with plug order.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import DeviceError
from .base import Camera

BY_ID = "/dev/v4l/by-id"


@dataclass
class CameraSettings:
    width: int = 2048
    height: int = 1536
    fourcc: str = "MJPG"  # UVC cameras give full resolution at a usable rate only as MJPG
    exposure: float = 156.0  # V4L2 exposure_time_absolute, 100 us units
    gain: float = 0.0
    wb_temperature: float = 4600.0
    focus: float = 0.0  # absolute focus, camera units; 0 = infinity on most UVC cameras
    flush: int = 4  # frames dropped after each move


def find_by_id(pattern: str = "") -> str:
    """The first /dev/v4l/by-id capture node whose name contains `pattern`."""
    try:
        names = sorted(n for n in os.listdir(BY_ID) if n.endswith("-video-index0") and pattern in n)
    except FileNotFoundError:
        names = []
    if not names:
        raise DeviceError("camera", f"no camera in {BY_ID} matching {pattern!r}: is it plugged in?")
    return os.path.join(BY_ID, names[0])


class V4L2Camera(Camera):
    def __init__(self, device: str, settings: CameraSettings | None = None):
        self.device, self.s = device, settings or CameraSettings()
        self.where = f"camera {device}"
        if not os.path.exists(device):
            raise DeviceError(self.where, "no such device: is the camera plugged in?")
        self._cap = cv2.VideoCapture(os.path.realpath(device), cv2.CAP_V4L2)
        if not self._cap.isOpened():
            raise DeviceError(self.where, "cannot open it with V4L2 (in use by another program?)")
        try:
            self._configure()
        except DeviceError:
            self._cap.release()
            raise

    def _set(self, prop, value, what):
        if not self._cap.set(prop, value):
            raise DeviceError(self.where, f"the camera refuses {what} = {value}")

    def _configure(self):
        s, cap = self.s, self._cap
        self._set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*s.fourcc), "pixel format " + s.fourcc)
        self._set(cv2.CAP_PROP_FRAME_WIDTH, s.width, "width")
        self._set(cv2.CAP_PROP_FRAME_HEIGHT, s.height, "height")
        got = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if got != (s.width, s.height):
            raise DeviceError(
                self.where, f"asked for {s.width}x{s.height}, the camera gives {got[0]}x{got[1]}"
            )
        cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        # V4L2 auto exposure menu: 1 = manual, 3 = aperture priority (auto)
        self._set(cv2.CAP_PROP_AUTO_EXPOSURE, 1, "manual exposure")
        self._set(cv2.CAP_PROP_EXPOSURE, s.exposure, "exposure")
        self._set(cv2.CAP_PROP_GAIN, s.gain, "gain")
        self._set(cv2.CAP_PROP_AUTO_WB, 0, "auto white balance off")
        self._set(cv2.CAP_PROP_WB_TEMPERATURE, s.wb_temperature, "white balance temperature")
        # Fixed-focus cameras have no focus control: that is as locked as it gets.
        if cap.set(cv2.CAP_PROP_AUTOFOCUS, 0):
            cap.set(cv2.CAP_PROP_FOCUS, s.focus)

    def capture(self) -> np.ndarray:
        for _ in range(self.s.flush):
            if not self._cap.grab():
                raise DeviceError(self.where, "no frame: the camera stopped delivering (unplugged?)")
        ok, frame = self._cap.read()
        if not ok or frame is None:
            raise DeviceError(self.where, "no frame: the camera stopped delivering (unplugged?)")
        if frame.shape[:2] != (self.s.height, self.s.width):
            raise DeviceError(
                self.where,
                f"frame is {frame.shape[1]}x{frame.shape[0]}, expected {self.s.width}x{self.s.height}",
            )
        return frame

    def close(self) -> None:
        self._cap.release()
