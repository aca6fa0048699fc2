"""The one way a test waits for something another thread or process does.

A test never sleeps a fixed time and hopes: it asks `wait_until` to call a condition
every few hundredths of a second until it gives a truthy value, and gets that value back
(the job that finished, the lines on the display, ...). If the time runs out the test
fails with what it was waiting for and the condition's last value; `what` may be a function,
called then, so the failure can say how far things got (the job's record, the display).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def wait_until(
    condition: Callable[[], T],
    timeout: float = 10.0,
    what: str | Callable[[], str] = "the condition",
    every: float = 0.02,
    ignoring: type[BaseException] | tuple[type[BaseException], ...] = (),
) -> T:
    """condition()'s first truthy value within `timeout` seconds, else AssertionError.
    Exceptions of the `ignoring` types count as "not yet" (a page element not there yet)."""
    end = time.monotonic() + timeout
    last: object = None
    while True:
        try:
            last = condition()
        except ignoring as e:
            last = e
        else:
            if last:
                return last
        if time.monotonic() >= end:
            said = what() if callable(what) else what
            raise AssertionError(f"timed out after {timeout:g} s waiting for {said} (last: {last!r})")
        time.sleep(every)
