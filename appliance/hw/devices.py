"""The devices a scan drives, and the factory that opens the real ones.

`Devices` is what the daemon gets from any factory (this one for the real
bench, appliance/sim/fakes.py for the simulated and fake ones). Optional
devices that are absent are None, with "missing" in `hardware`, so the daemon
reports them once and carries on; the stage and the camera are required.

The real bench's wiring comes from a small JSON file (/etc/inkslice/bench.json,
all keys optional):

    {"stage_port": "/dev/inkslice-stage", "camera": "/dev/inkslice-camera",
     "camera_settings": {"width": 2048, "height": 1536, "exposure": 156},
     "gpiochip": "/dev/gpiochip0", "light_line": 17, "led_line": 27,
     "button_line": 22, "mcu_reset_line": 23,
     "i2c_bus": 1, "display_address": 60, "level_sensor_address": null,
     "level_sensor_mount_mm": 120.0}
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import DeviceError, InkSliceError, SettingError
from .base import BenchFactory

log = logging.getLogger("inkslice.devices")

WIRING = {
    "stage_port": "/dev/inkslice-stage",
    "camera": "/dev/inkslice-camera",
    "camera_settings": {},
    "gpiochip": "/dev/gpiochip0",
    "light_line": 17,
    "led_line": 27,
    "button_line": 22,
    "mcu_reset_line": 23,
    "i2c_bus": 1,
    "display_address": 0x3C,
    "level_sensor_address": None,
    "level_sensor_mount_mm": 120.0,
}


@dataclass
class Devices:
    """What a scan drives. light/led/display/button/level_sensor may be None (missing)."""

    stage: object
    camera: object
    camera_model: object = None  # vision.camera.CameraModel, or None: use the calibration
    light: object = None
    led: object = None
    display: object = None
    button: object = None
    level_sensor: object = None
    operator: object = None  # hw.base.Operator (the panel's): who places things on the base
    hardware: dict = field(default_factory=dict)  # name -> "ok" | "missing" | "fault: ..."
    closers: list = field(default_factory=list)  # called by close(), in order

    def close(self):
        for c in self.closers:
            try:
                c()
            except Exception:  # closing must never hide the real error
                log.exception("closing a device")

    def capture_lit(self):
        """One frame, with the light on only while it is taken."""
        if self.light is not None:
            self.light.set(True)
        try:
            return self.camera.capture()
        finally:
            if self.light is not None:
                self.light.set(False)

    def release(self):
        """Light off, then every device closed: how any use of the bench ends, however it ends."""
        if self.light is not None:
            try:
                self.light.set(False)
            except Exception:
                log.warning("could not switch the light off while releasing the bench")
        self.close()


def load_wiring(path) -> dict:
    if path is None or not Path(path).is_file():
        return dict(WIRING)
    try:
        doc = json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SettingError(path, f"not valid JSON ({e})") from None
    unknown = set(doc) - set(WIRING)
    if unknown:
        raise SettingError(path, f"unknown key {sorted(unknown)[0]!r}; known: {', '.join(WIRING)}")
    return {**WIRING, **doc}


def _optional(hardware, name, opener):
    """Open an optional device; None and 'missing' (reported once by the daemon) when absent."""
    try:
        dev = opener()
    except (InkSliceError, OSError, ImportError) as e:
        hardware[name] = f"missing ({e})"
        return None
    hardware[name] = "ok"
    return dev


class HardwareBench(BenchFactory):
    """Device factory for the real bench (see hw/base.py BenchFactory)."""

    def __init__(self, wiring: dict | None = None):
        self.w = {**WIRING, **(wiring or {})}

    def _reset_mcu(self):
        from .gpio import GpioOutput, pulse

        line = GpioOutput(self.w["gpiochip"], self.w["mcu_reset_line"], "mcu-reset", active_low=True)
        try:
            pulse(line, 0.05)
        finally:
            line.close()

    def _open_stage(self):
        from .stage import SerialStage

        try:
            # auto_rehome=False: a reset mid-scan must stop the job with a reason, not be hidden
            return SerialStage(self.w["stage_port"], auto_rehome=False)
        except DeviceError as first:
            # a wedged controller: pulse its reset line once and try again
            try:
                self._reset_mcu()
            except (InkSliceError, OSError, ImportError):
                raise first from None
            import time

            time.sleep(2.0)  # the bootloader's wait
            return SerialStage(self.w["stage_port"], auto_rehome=False)

    def open(self, settings, params) -> Devices:
        from .camera import CameraSettings, V4L2Camera
        from .gpio import GpioOutput

        hw = {}
        stage = self._open_stage()
        hw["stage"] = "ok"
        try:
            camera = V4L2Camera(self.w["camera"], CameraSettings(**self.w["camera_settings"]))
        except Exception:
            stage.close()
            raise
        hw["camera"] = "ok"
        light = _optional(hw, "light", lambda: GpioOutput(self.w["gpiochip"], self.w["light_line"], "light"))
        sensor = None
        if self.w["level_sensor_address"] is not None:
            from .sensors import Vl6180xLevel

            sensor = _optional(
                hw,
                "level_sensor",
                lambda: Vl6180xLevel(
                    self.w["level_sensor_mount_mm"], self.w["i2c_bus"], self.w["level_sensor_address"]
                ),
            )
        closers = (
            [camera.close, stage.close]
            + ([light.close] if light else [])
            + ([sensor.close] if sensor else [])
        )
        return Devices(stage, camera, None, light=light, level_sensor=sensor, hardware=hw, closers=closers)

    def open_panel(self) -> Devices:
        from .display import Ssd1306
        from .gpio import GpioButton, GpioOutput

        hw = {}
        led = _optional(hw, "led", lambda: GpioOutput(self.w["gpiochip"], self.w["led_line"], "led"))
        button = _optional(hw, "button", lambda: GpioButton(self.w["gpiochip"], self.w["button_line"]))
        display = _optional(hw, "display", lambda: Ssd1306(self.w["i2c_bus"], self.w["display_address"]))
        closers = [d.close for d in (led, button, display) if d is not None]
        from .base import HumanOperator

        return Devices(
            None,
            None,
            led=led,
            button=button,
            display=display,
            operator=HumanOperator(),
            hardware=hw,
            closers=closers,
        )
