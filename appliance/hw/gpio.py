"""GPIO lines on the SBC through libgpiod's v2 Python API.

The light (on only while a frame is taken), the status LED and the MCU's
reset line are outputs; the start/stop button is an input with the pull-up
on and kernel debouncing. Lines are named by chip + offset (a bench setting),
never by a global numbering that changes between kernels.

Missing hardware is not an error for the daemon: `open_output`/`open_button`
return None with a reason, and the daemon reports "missing" once and carries
on without that line.
"""
from __future__ import annotations

import datetime
import time

from ..errors import DeviceError
from .base import OutputLine


class GpioOutput(OutputLine):
    def __init__(self, chip: str, offset: int, name: str, active_low: bool = False):
        import gpiod
        from gpiod.line import Direction, Value
        self._Value = Value
        self.name, self.offset = name, offset
        try:
            self._req = gpiod.request_lines(
                chip, consumer=f"inkslice-{name}",
                config={offset: gpiod.LineSettings(direction=Direction.OUTPUT, active_low=active_low,
                                                   output_value=Value.INACTIVE)})
        except (OSError, ValueError) as e:
            raise DeviceError(f"gpio {name} ({chip} line {offset})", f"cannot request the line: {e}") from None

    def set(self, on: bool) -> None:
        try:
            self._req.set_value(self.offset, self._Value.ACTIVE if on else self._Value.INACTIVE)
        except OSError as e:
            raise DeviceError(f"gpio {self.name}", f"cannot set the line: {e}") from None

    def close(self):
        try:
            self.set(False)          # leave the light / LED off
        finally:
            self._req.release()


class GpioButton:
    """A push button to ground (pull-up on, 30 ms debounce); poll() is True once per press."""

    def __init__(self, chip: str, offset: int, name: str = "button"):
        import gpiod
        from gpiod.line import Bias, Direction, Edge
        self.name, self.offset = name, offset
        try:
            self._req = gpiod.request_lines(
                chip, consumer=f"inkslice-{name}",
                config={offset: gpiod.LineSettings(direction=Direction.INPUT, bias=Bias.PULL_UP,
                                                   active_low=True, edge_detection=Edge.RISING,
                                                   debounce_period=datetime.timedelta(milliseconds=30))})
        except (OSError, ValueError) as e:
            raise DeviceError(f"gpio {name} ({chip} line {offset})", f"cannot request the line: {e}") from None

    def poll(self) -> bool:
        pressed = False
        while self._req.wait_edge_events(datetime.timedelta(0)):
            pressed = pressed or bool(self._req.read_edge_events())
        return pressed

    def close(self):
        self._req.release()


def pulse(line: OutputLine, seconds: float = 0.05):
    """Pulse a line (the MCU's reset: active for `seconds`, then released)."""
    line.set(True)
    time.sleep(seconds)
    line.set(False)
