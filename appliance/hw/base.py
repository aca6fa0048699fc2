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
    state: str                 # firmware state name, e.g. "idle", "moving", "homing", "alarm"
    position_steps: int
    position_mm: float
    homed: bool
    flags: dict = field(default_factory=dict)   # limit switches, e-stop, ...


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

    def close(self) -> None:
        pass


class Camera(abc.ABC):
    """A fixed camera looking down at the liquid plane."""

    @abc.abstractmethod
    def capture(self) -> np.ndarray:
        """One fresh 8-bit BGR frame taken after the last move settled."""

    def close(self) -> None:
        pass


class OutputLine(abc.ABC):
    """A GPIO output: the light, the status LED, the MCU's reset line."""

    @abc.abstractmethod
    def set(self, on: bool) -> None: ...


class Display(abc.ABC):
    """A small status display (e.g. SSD1306 over I2C)."""

    @abc.abstractmethod
    def show(self, lines: list[str]) -> None: ...
