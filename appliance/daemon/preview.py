"""The live preview: the newest camera frame and the height map so far, for the dashboard.

Why apart from the service: both are pictures of a scan for people to watch, never part of
the result. They are made from what the runner hands over per frame (the image and its part
mask), kept in memory only, and a failure here must never fail the scan.

    latest()           (jpeg bytes, info) of the newest frame, None before the first
    show(jpeg, info)   a frame someone else already encoded (the machine panel, calibration)
    keep(image, info, job_dir, width)   a scan's frame: downscaled, the waterline drawn in red,
                       and its part mask added to the live height map
    heightmap()        livemap.LiveMap.to_json() of the current (or last) scan, None before one
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import cv2
import numpy as np

from ..scanfile import load_scan
from .livemap import LiveMap

log = logging.getLogger("inkslice.preview")
JPEG_QUALITY = 80
WATERLINE_BGR = (0, 0, 255)


class Preview:
    def __init__(self):
        self._lock = threading.Lock()
        self._frame: tuple[bytes, dict] | None = None
        self._live: tuple[str, LiveMap] | None = None  # (job id, its height map so far)

    def latest(self) -> tuple[bytes, dict] | None:
        with self._lock:
            return self._frame

    def show(self, jpeg: bytes, info: dict) -> None:
        with self._lock:
            self._frame = (jpeg, info)

    def clear(self) -> None:
        """A new scan starts: the last one's frame is no longer news."""
        with self._lock:
            self._frame = None

    def heightmap(self) -> dict | None:
        with self._lock:
            live = self._live
        return live[1].to_json() if live else None

    def keep(self, image: np.ndarray, info: dict, job_id: str, job_dir: Path, width: int) -> None:
        """A scan's frame for latest(); `info["part"]` (the runner's part mask) is taken out of info."""
        h, w = image.shape[:2]
        width = min(w, int(width))
        small = cv2.resize(image, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)
        if small.ndim == 2:
            small = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
        part = info.pop("part")  # vision/part.py's mask of the part above the ink
        mask = cv2.resize(
            part.astype(np.uint8), (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST
        )
        contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(small, contours, -1, WATERLINE_BGR, 2, cv2.LINE_AA)
        ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if ok:
            self.show(buf.tobytes(), {**info, "waterline": bool(contours)})
        self._grow_live_map(part, info.get("level_mm"), job_id, job_dir)

    def _grow_live_map(self, part, level_mm, job_id: str, job_dir: Path) -> None:
        try:
            live = self._live
            if live is None or live[0] != job_id:
                live = (job_id, LiveMap(load_scan(job_dir / "scan").camera))
            if level_mm is not None:
                live[1].add(part, float(level_mm))
            with self._lock:
                self._live = live
        except Exception as e:  # a preview must never fail the scan
            log.warning("live height map: %s", e)
