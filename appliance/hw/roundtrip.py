"""RoundTrip: how long the stage driver waits for one reply, measured on the line.

The wait is the smoothed round trip plus four deviations, as TCP does (Jacobson/Karels),
never below a floor, and half as long again after each wait that ended in silence. Only the
reply to a line sent once is a sample (Karn's rule: a resent line's reply is ambiguous).
hw/stage.py gives each command ATTEMPTS such waits, or its timeout if longer."""

from __future__ import annotations

MAX_WAIT_S = 2.0  # no single wait for a reply is longer, however slow the line looked


class RoundTrip:
    """The line's reply time, as measured so far (the rules: the module's docstring)."""

    def __init__(self, floor: float):
        self.floor = floor
        self.srtt: float | None = None
        self.var = 0.0
        self.carry = floor  # grown by silence, kept until the next clean sample
        self.worst = 0.0

    def sample(self, rtt: float) -> None:
        self.worst = max(self.worst, rtt)
        if self.srtt is None:
            self.srtt, self.var = rtt, rtt / 2
        else:
            self.var += (abs(self.srtt - rtt) - self.var) / 4
            self.srtt += (rtt - self.srtt) / 8
        self.carry = self.floor

    def wait(self) -> float:
        """How long to wait for one reply before sending again."""
        base = self.floor if self.srtt is None else self.srtt + 4 * self.var
        return min(MAX_WAIT_S, max(self.floor, base, self.carry))

    def silence(self) -> None:
        """A wait ended without a reply: the next ones wait half as long again (a slow link then
        gets replies within the wait, hence samples; a lost byte costs one longer wait)."""
        self.carry = min(MAX_WAIT_S, self.wait() * 1.5)
