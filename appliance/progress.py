"""Progress of long commands (process, toolpath, verify, render), as the person at the shell sees it.

Library code says where it is with two calls that cost nothing when nobody listens:

    progress.stage("waterlines", total=len(frames))     # a new stage (total: its count, if known)
    progress.step(i + 1)                                 # so far in the current stage

A command shows them inside `with progress.shown():`. On a terminal that is one line per stage,
redrawn in place: a bar with the count for a counted stage, the seconds so far for the others
(a ticker keeps it moving while a single step takes long). Anywhere else (a pipe, a log, a test)
it is plain lines: the stage's start, every quarter of a counted stage, and how long it took.
The daemon's processing child has no display: it only clocks the stages (`timed`), so a job's
log says where its processing time went.
"""

from __future__ import annotations

import resource
import sys
import threading
import time
from contextlib import contextmanager

BAR = 24
TICKER = "progress"  # the bar's redrawing thread (forks.py knows it is harmless)
TICK_S = 0.25
_display = None


def stage(name: str, total: int | None = None) -> None:
    if _display is not None:
        _display.stage(name, total)


def step(done: int, total: int | None = None) -> None:
    if _display is not None:
        _display.step(done, total)


@contextmanager
def shown(stream=None, tty: bool | None = None):
    """Show the stages reported inside the block on `stream` (default stdout)."""
    global _display
    stream = stream or sys.stdout
    if tty is None:
        tty = bool(getattr(stream, "isatty", lambda: False)())
    previous, _display = _display, Display(stream, tty)
    swapped = tty and stream is sys.stdout
    if swapped:
        sys.stdout = _AroundTheBar(stream, _display)  # a print() mid-stage goes above the bar
    try:
        yield _display
    finally:
        if swapped:
            sys.stdout = stream
        _display.close()
        _display = previous


def peak_mb() -> float:
    """This process's own peak resident memory in MB. Not ru_maxrss: a process started by
    fork and exec keeps in it what its parent held when it forked (a daemon's 180 MB made a
    processing child of 100 look like 220); the kernel's VmHWM is this program's alone."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB (not Linux)


@contextmanager
def timed():
    """Clock the stages reported inside the block: yields a _StageClock whose `seconds`
    ({stage: seconds}) and `peak_mb` ({stage: the process's peak memory when it ended}) fill as they end."""
    global _display
    previous, _display = _display, _StageClock()
    try:
        yield _display
    finally:
        _display.close()
        _display = previous


class _StageClock:
    def __init__(self):
        self.seconds: dict[str, float] = {}
        self.peak_mb: dict[str, float] = {}
        self.name, self.t0 = None, 0.0

    def stage(self, name, total=None):
        self.close()
        self.name, self.t0 = name, time.monotonic()

    def step(self, done, total=None):
        pass

    def close(self):
        if self.name is not None:
            self.seconds[self.name] = self.seconds.get(self.name, 0.0) + time.monotonic() - self.t0
            self.peak_mb[self.name] = peak_mb()
            self.name = None


class _AroundTheBar:
    """stdout while a bar is drawn: the bar line is cleared before other text and drawn again after."""

    def __init__(self, stream, display):
        self._stream, self._display = stream, display

    def write(self, text):
        with self._display.lock:
            self._stream.write("\r\x1b[K" + text)
            if text.endswith("\n") and self._display.name is not None:
                self._stream.write(self._display.line())
        return len(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


class Display:
    def __init__(self, stream, tty: bool):
        self.stream, self.tty = stream, tty
        self.lock = threading.Lock()
        self.name = None
        self.total = None
        self.done = 0
        self.t0 = 0.0
        self.quarter = 0
        self.stop = threading.Event()
        self.ticker = None
        if tty:
            self.ticker = threading.Thread(target=self._tick, name=TICKER, daemon=True)
            self.ticker.start()

    def stage(self, name, total=None):
        with self.lock:
            self._finish()
            self.name, self.total, self.done, self.t0, self.quarter = name, total, 0, time.monotonic(), 0
            if self.tty:
                self._draw()
            else:
                self._say(f"{name} ..." + (f" ({total})" if total else ""))

    def step(self, done, total=None):
        with self.lock:
            if self.name is None:
                return
            self.done = done
            if total is not None:
                self.total = total
            if self.tty:
                self._draw()
            elif self.total:
                q = int(4 * self.done / self.total)
                if q > self.quarter and q < 4:
                    self.quarter = q
                    self._say(f"{self.name}: {25 * q} % ({self.done}/{self.total}, {self._elapsed()})")

    def close(self):
        self.stop.set()
        if self.ticker is not None:
            self.ticker.join(timeout=1)
        with self.lock:
            self._finish()

    # -- drawing ----------------------------------------------------------------------------
    def _elapsed(self):
        s = time.monotonic() - self.t0
        return f"{s:.1f} s" if s < 60 else f"{int(s) // 60} min {int(s) % 60:02d} s"

    def line(self):
        if self.total:
            frac = min(1.0, self.done / self.total)
            fill = int(round(BAR * frac))
            return (
                f"{self.name} [{'#' * fill}{'-' * (BAR - fill)}] {100 * frac:3.0f} % "
                f"{self.done}/{self.total} · {self._elapsed()}"
            )
        return f"{self.name} ... {self._elapsed()}"

    def _draw(self):
        self.stream.write("\r\x1b[K" + self.line())
        self.stream.flush()

    def _say(self, text):
        self.stream.write(text + "\n")
        self.stream.flush()

    def _finish(self):
        if self.name is None:
            return
        if self.total:
            self.done = self.total if self.done >= self.total else self.done
        if self.tty:
            self.stream.write("\r\x1b[K" + self.line() + " done\n")
            self.stream.flush()
        else:
            self._say(f"{self.name}: done in {self._elapsed()}")
        self.name = None

    def _tick(self):
        while not self.stop.wait(TICK_S):
            with self.lock:
                if self.name is not None:
                    self._draw()
