"""The one error type users see.

Every problem a user can act on (a bad file, a bad setting, a device that is
missing) is raised as an InkSliceError that names *where* (a file, a setting,
a device) and *what* is wrong. The CLI prints it as one line and exits 2; the
web UI and the daemon store the same text with the job.
"""


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
