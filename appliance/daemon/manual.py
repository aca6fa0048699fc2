"""The machine panel between scans: a live preview, home, jog and go to a level.

Why a session: the stage and camera are opened once for a run of panel requests (a serial port
and a camera open only once), the light stays on while someone watches the preview, and
everything is closed again, light off, IDLE_S after the last request: a phone that went to sleep
leaves the bench dark and free. A scan, a calibration or a commissioning step closes the session
before it opens the devices itself.

Levels are the ink's height above the base top, as in a scan: level = level_at_home_mm - stage
position. "Up" lifts the base (the part rises out of the ink: the level falls).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import cv2

from ..errors import DeviceError, SettingError

log = logging.getLogger("inkslice.manual")
IDLE_S = 20.0  # the light goes off and the devices close this long after the last request
FRAME_EVERY_S = 0.8  # a preview request newer than this reuses the last frame (many phones, one camera)
JOG_STEPS_MM = (0.1, 1.0, 10.0)


class ManualSession:
    def __init__(
        self,
        open_devices: Callable,
        settings: Callable,
        show_frame: Callable,
        report: Callable,
        idle_s: float = IDLE_S,
        clock=time.monotonic,
    ):
        self._open_devices = open_devices  # () -> hw.devices.Devices
        self._settings = settings  # () -> the daemon's settings
        self._show_frame = show_frame  # (jpeg, info): the dashboard's latest frame
        self._report = report  # (status dict, hardware dict): into the daemon's state
        self.idle_s = idle_s
        self.clock = clock
        self._lock = threading.RLock()
        self._devices = None
        self._last_use = 0.0
        self._last_frame = -1e9
        self._timer: threading.Timer | None = None

    # -- what the panel asks -------------------------------------------------------------
    def preview(self) -> dict:
        """Keep the session (and the light) on; take a fresh frame unless one is very recent."""
        with self._lock:
            dev = self._use()
            if self.clock() - self._last_frame >= FRAME_EVERY_S:
                self._capture(dev)
            return self.status()

    def home(self) -> dict:
        with self._lock:
            dev = self._use()
            dev.stage.home()
            self._capture(dev)
            return self._publish()

    def jog(self, mm: float) -> dict:
        """Move the base up (mm > 0) or down by mm from where it is; the stage must be homed."""
        mm = _number("jog", mm)
        if abs(mm) not in JOG_STEPS_MM:
            raise SettingError("jog", f"{mm} mm: jog by ±{', '.join(f'{s:g}' for s in JOG_STEPS_MM)} mm")
        with self._lock:
            dev = self._use()
            st = self._homed(dev)
            self._move(dev, st.position_mm + mm)
            return self._publish()

    def goto(self, level_mm: float) -> dict:
        """Put the ink at level_mm above the base top (the stage must be homed)."""
        level_mm = _number("level", level_mm)
        with self._lock:
            dev = self._use()
            self._homed(dev)
            self._move(dev, self._at_home() - level_mm, what=f"level {level_mm:g} mm")
            return self._publish()

    def status(self) -> dict:
        with self._lock:
            dev = self._devices
            if dev is None:
                return {"open": False, "light": False, "homed": False, "level_mm": None}
            try:
                st = dev.stage.status()
            except Exception as e:  # a stage that stopped answering: say so, carry on
                return {
                    "open": True,
                    "light": dev.light is not None,
                    "homed": False,
                    "level_mm": None,
                    "problem": str(e),
                }
            return {
                "open": True,
                "light": dev.light is not None,
                "homed": bool(st.homed),
                "level_mm": round(self._at_home() - st.position_mm, 3) if st.homed else None,
            }

    @property
    def active(self) -> bool:
        return self._devices is not None

    def close(self) -> None:
        """Light off, devices closed (idempotent): before a scan, or IDLE_S after the last request."""
        with self._lock:
            dev, self._devices = self._devices, None
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
        if dev is None:
            return
        try:
            if dev.light is not None:
                dev.light.set(False)
        except Exception as e:
            log.warning("panel: light off: %s", e)
        dev.close()
        self._report({"open": False, "light": False, "homed": False, "level_mm": None}, None)

    # -- internals ------------------------------------------------------------------------
    def _use(self):
        """The open devices (opened, light on, on first use); restarts the idle timer."""
        if self._devices is None:
            try:
                dev = self._open_devices()
            except DeviceError:
                raise
            except Exception as e:
                raise DeviceError("bench", f"cannot open the stage and camera: {e}") from None
            if dev.stage is None or dev.camera is None:
                dev.close()
                raise DeviceError("bench", "no stage or camera on this bench")
            if dev.light is not None:
                dev.light.set(True)
            self._devices = dev
            self._report(self.status(), dict(dev.hardware))
        self._last_use = self.clock()
        self._arm()
        return self._devices

    def _arm(self):
        if self._timer is not None:
            self._timer.cancel()
        self._timer = threading.Timer(self.idle_s, self._idle_check)
        self._timer.daemon = True
        self._timer.start()

    def _idle_check(self):
        with self._lock:
            if self._devices is None or self.clock() - self._last_use < self.idle_s * 0.95:
                return
        log.info("panel: no request for %.0f s, light off and devices closed", self.idle_s)
        self.close()

    def _at_home(self) -> float:
        return float(self._settings()["level_at_home_mm"])

    @staticmethod
    def _homed(dev):
        st = dev.stage.status()
        if not st.homed:
            raise SettingError("stage", "not homed: home the stage first (its position is unknown)")
        return st

    def _move(self, dev, position_mm, what=None):
        lo, hi = dev.stage.travel_mm()
        if not lo - 1e-9 <= position_mm <= hi + 1e-9:
            at_home = self._at_home()
            raise SettingError(
                "stage",
                f"{what or 'that move'} is outside the travel: levels "
                f"{at_home - hi:g} to {at_home - lo:g} mm",
            )
        dev.stage.move_to(position_mm)
        self._capture(dev)

    def _capture(self, dev):
        frame = dev.camera.capture()
        if frame is None or frame.ndim not in (2, 3):
            raise DeviceError("camera", "returned no image")
        width = min(frame.shape[1], int(self._settings().get("preview_width", 480)))
        h = max(1, round(frame.shape[0] * width / frame.shape[1]))
        small = cv2.resize(frame, (width, h), interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 80])
        if not ok:
            raise DeviceError("camera", "the frame could not be encoded")
        st = self.status()
        self._show_frame(buf.tobytes(), {"time": time.time(), "level_mm": st["level_mm"], "preview": True})
        self._last_frame = self.clock()

    def _publish(self) -> dict:
        st = self.status()
        self._report(st, None)
        return st


def _number(where, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SettingError(where, f"{value!r} is not a number of mm") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise SettingError(where, f"{value!r} is not a number of mm")
    return v
