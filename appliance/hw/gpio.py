"""GPIO lines on the SBC through libgpiod's v2 Python API.

The light (on only while a frame is taken), the status LED and the MCU's
reset line are outputs; the start/stop button is an input with the pull-up
on and kernel debouncing. The button tells a short press (start/stop) from a
long one (held LONG_PRESS_S: copy the latest G-code to the USB stick); the
long press is reported while the button is still held, so the operator sees
the bench react without having to guess when to let go. Lines are named by chip + offset (a bench setting),
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


def request_line(chip: str, offset: int, name: str, settings):
    """One line of `chip`, held by us as inkslice-NAME until released."""
    import gpiod

    try:
        return gpiod.request_lines(chip, consumer=f"inkslice-{name}", config={offset: settings})
    except (OSError, ValueError) as e:
        raise DeviceError(f"gpio {name} ({chip} line {offset})", f"cannot request the line: {e}") from None


class GpioOutput(OutputLine):
    def __init__(self, chip: str, offset: int, name: str, active_low: bool = False):
        import gpiod
        from gpiod.line import Direction, Value

        self._Value = Value
        self.name, self.offset = name, offset
        out = gpiod.LineSettings(
            direction=Direction.OUTPUT, active_low=active_low, output_value=Value.INACTIVE
        )
        self._req = request_line(chip, offset, name, out)

    def set(self, on: bool) -> None:
        try:
            self._req.set_value(self.offset, self._Value.ACTIVE if on else self._Value.INACTIVE)
        except OSError as e:
            raise DeviceError(f"gpio {self.name}", f"cannot set the line: {e}") from None

    def close(self):
        try:
            self.set(False)  # leave the light / LED off
        finally:
            self._req.release()


LONG_PRESS_S = 2.0
SHORT, LONG = "short", "long"


class PressTimer:
    """Press and release edges in, "short" / "long" presses out (pure; tests drive it).

    A press held for long_s is "long" as soon as check() sees it held that long (its
    release then says nothing); a press released earlier is "short".
    """

    def __init__(self, long_s: float = LONG_PRESS_S):
        self.long_s = float(long_s)
        self._down: float | None = None
        self._fired = False

    def edge(self, pressed: bool, t: float) -> str | None:
        if pressed:
            if self._down is None:  # a second "down" without an "up" (a lost edge): keep the first
                self._down, self._fired = t, False
            return None
        down, fired, self._down = self._down, self._fired, None
        if down is None or fired:  # released after a long press, or held since before we started
            return None
        return LONG if t - down >= self.long_s else SHORT

    def check(self, now: float) -> str | None:
        if self._down is not None and not self._fired and now - self._down >= self.long_s:
            self._fired = True
            return LONG
        return None


class GpioButton:
    """A push button to ground (pull-up on, 30 ms debounce).

    poll() returns "short" or "long" once per press (see PressTimer), else None.
    Edges carry the kernel's CLOCK_MONOTONIC timestamps, so a busy daemon that
    polls late still measures the press as the operator made it.
    """

    def __init__(self, chip: str, offset: int, name: str = "button", long_s: float = LONG_PRESS_S):
        import gpiod
        from gpiod.line import Bias, Direction, Edge

        self.name, self.offset = name, offset
        pulled_up = gpiod.LineSettings(
            direction=Direction.INPUT,
            bias=Bias.PULL_UP,
            active_low=True,
            edge_detection=Edge.BOTH,
            debounce_period=datetime.timedelta(milliseconds=30),
        )
        self._req = request_line(chip, offset, name, pulled_up)
        from gpiod.edge_event import EdgeEvent

        self._rising = EdgeEvent.Type.RISING_EDGE  # active-low: rising = pressed
        self._timer = PressTimer(long_s)

    def poll(self) -> str | None:
        got = None
        while self._req.wait_edge_events(datetime.timedelta(0)):
            for ev in self._req.read_edge_events():
                kind = self._timer.edge(ev.event_type == self._rising, ev.timestamp_ns / 1e9)
                got = got or kind
        return got or self._timer.check(time.monotonic())

    def close(self):
        self._req.release()


def pulse(line: OutputLine, seconds: float = 0.05):
    """Pulse a line (the MCU's reset: active for `seconds`, then released)."""
    line.set(True)
    time.sleep(seconds)
    line.set(False)
