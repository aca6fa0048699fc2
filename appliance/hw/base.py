"""The interfaces the daemon drives. Real devices, the virtual bench and the
test fakes all implement these, so the daemon cannot tell them apart.

Levels: the stage lifts the base. `position_mm` is the stage's height above
its home switch; the liquid level above the base top is then
    level_mm = level_at_home_mm - position_mm
where `level_at_home_mm` is a bench setting (found by calibration).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field

import numpy as np


@dataclass
class StageStatus:
    state: str  # firmware state name, e.g. "idle", "moving", "homing", "alarm"
    position_steps: int
    position_mm: float
    homed: bool
    flags: dict = field(default_factory=dict)  # limit switches, e-stop, ...


class Stage(abc.ABC):
    """The lifting stage (the AVR firmware over serial, or a fake)."""

    @abc.abstractmethod
    def identify(self) -> dict: ...

    @abc.abstractmethod
    def home(self, timeout: float = 60.0) -> None: ...

    @abc.abstractmethod
    def move_to(self, position_mm: float, timeout: float = 60.0) -> None:
        """Move to an absolute position and return when the motion is done."""

    @abc.abstractmethod
    def status(self) -> StageStatus: ...

    @abc.abstractmethod
    def stop(self) -> None:
        """Emergency stop: halt now; position is then unknown until re-homed."""

    @abc.abstractmethod
    def travel_mm(self) -> tuple[float, float]:
        """The lowest and highest positions a move may ask for (the soft limits), mm above home.
        The lowest sets the highest level a scan can start at (see daemon/levels.py)."""

    def close(self) -> None:  # noqa: B027 (optional: a device with nothing to release keeps it)
        """Release the device; the default has nothing to release."""


class Camera(abc.ABC):
    """A fixed camera looking down at the liquid plane."""

    @abc.abstractmethod
    def capture(self) -> np.ndarray:
        """One fresh 8-bit BGR frame taken after the last move settled."""

    def close(self) -> None:  # noqa: B027 (optional: a device with nothing to release keeps it)
        """Release the device; the default has nothing to release."""


class OutputLine(abc.ABC):
    """A GPIO output: the light, the status LED, the MCU's reset line."""

    @abc.abstractmethod
    def set(self, on: bool) -> None: ...


class Display(abc.ABC):
    """A small status display (e.g. SSD1306 over I2C)."""

    @abc.abstractmethod
    def show(self, lines: list[str]) -> None: ...


@dataclass
class Placement:
    """What the bench needs on its base (or in front of the camera) for a commissioning step.

    kind: "empty"        nothing on the base
          "board_views"  the printed chessboard held tilted under the camera; `view` counts them
          "board_flat"   the chessboard lying flat on the base at `board`'s jig position
          "reference"    the reference part on the base (`details`: part, diameter_mm)
          "clear"        the step is over: take off what it asked for, the bench is yours again
    text: the request in words, for the operator (display, web page).
    details: the numbers behind the request (board size and jig position, the ball's diameter, ...).
    """

    kind: str
    text: str
    details: dict = field(default_factory=dict)
    view: int = 0

    def to_json(self) -> dict:
        return {"kind": self.kind, "text": self.text, "details": dict(self.details), "view": self.view}


class Operator(abc.ABC):
    """Whoever puts things on the base. On a real box that is a person, who reads the request
    on the display and the phone (HumanOperator); the simulated bench places the object itself."""

    @abc.abstractmethod
    def place(self, request: Placement) -> None:
        """Ask for `request`; returns at once (a person then does it and presses on in the wizard)."""


class HumanOperator(Operator):
    """The real box: the request is only a message. The daemon shows `current.text` to the person."""

    def __init__(self):
        self.current: Placement | None = None

    def place(self, request: Placement) -> None:
        self.current = request


class BenchFactory(abc.ABC):
    """Opens the devices the daemon drives: the real bench (hw/devices.py), the
    simulated one and the in-memory fakes (sim/fakes.py). The daemon knows no
    more of a bench than this."""

    extra_params: tuple = ()  # scan parameters start_scan accepts beyond the settings
    calibration_target: dict = {}  # the guided calibration's board and pose, when not the printed default

    @abc.abstractmethod
    def open(self, settings: dict, params: dict):
        """The devices for one scan (hw.devices.Devices): stage, camera, light, camera model..."""

    @abc.abstractmethod
    def open_panel(self):
        """The front panel (hw.devices.Devices): LED, button, display, each possibly missing."""

    def check(self, params: dict) -> dict:
        """The extra scan parameters, checked (SettingError) and completed."""
        return params

    def disk_free_mb(self, path) -> float:
        """Free space where the scans are written; scans stop before the disk is full."""
        import shutil

        return shutil.disk_usage(path).free / 1e6

    def usb(self):
        """What copies G-code to a USB stick (hw.usb.UsbExporter), or None for no USB export."""
        from .usb import UsbExporter

        return UsbExporter()

    def close(self) -> None:  # noqa: B027 (optional: a device with nothing to release keeps it)
        """Release the device; the default has nothing to release."""
