"""The one error type users see.

Every problem a user can act on (a bad file, a bad setting, a device that is
missing) is raised as an InkSliceError that names *where* (a file, a setting,
a device) and *what* is wrong. The CLI prints it as one line and exits 2; the
web UI and the daemon store the same text with the job.
"""

import math


class InkSliceError(Exception):
    def __init__(self, where, problem):
        self.where = str(where)
        self.problem = str(problem)
        super().__init__(f"{self.where}: {self.problem}")


class ScanError(InkSliceError):
    """A scan folder, its scan.json or one of its frames is unusable."""


class SettingError(InkSliceError):
    """A setting is impossible (a negative feed, a step of zero, ...)."""


class DeviceError(InkSliceError):
    """A device (stage, camera, light, display) failed or is missing."""


class Cancelled(Exception):
    """A running job (a scan, its processing, a reference fit) was asked to stop.

    Not an InkSliceError: nothing is wrong, and whoever stopped it already knows why.
    It lives here, beside the errors, because the runner, the processing and the
    commissioning all raise or catch it and none of them should import another for it."""


def check_mm(where: str, value, *, zero_ok: bool = False, what: str = "") -> None:
    """A length that must be a number of mm above zero (at or above, with zero_ok), else a
    SettingError: `check_mm("cutter", d, what="diameter")` -> "cutter: diameter must be > 0 mm, got 0"."""
    if value is None or not math.isfinite(value) or (value < 0 if zero_ok else value <= 0):
        bound = ">= 0" if zero_ok else "> 0"
        raise SettingError(where, f"{what + ' ' if what else ''}must be {bound} mm, got {value}")
