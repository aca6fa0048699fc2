"""USB export as the daemon does it: which job file goes onto the stick, and the outcome.

Why here and not in hw/usb.py: choosing a file needs the job records (their status, their
outputs, newest first), which are the daemon's. hw/usb.py is the device side: it finds the
sticks, copies the file it is given (verified), syncs and unmounts; it knows nothing of jobs.

    UsbExport(exporter, store, job_file, notify)
        exporter: hw.usb.UsbExporter (sticks(), export()), or None when USB export is off
        job_file(job_id, name) -> Path: BenchService.job_file, the one rule for a job's files
        notify(notice) -> notice: the front panel's display, state()["notice"] and event log
    sticks()                       the sticks plugged in, as JSON
    export(job_id, name, stick)    the web's copy of one job file (raises InkSliceError)
    latest_gcode()                 (job id, file name) the long press would copy, or None
    export_latest()                the long press: an outcome notice, never an exception
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from ..errors import DeviceError, InkSliceError
from ..hw.usb import NoStick
from .notices import usb_notice
from .processing import PROGRAM
from .store import Store

log = logging.getLogger("inkslice.usb")
GCODE_SUFFIXES = (".gcode", ".nc", ".ngc", ".tap")


def latest_gcode(store: Store) -> tuple[str, str] | None:
    """(job id, file name) of the newest finished job's finishing program (or, for a job
    without one, its first G-code file); None when no finished job has G-code."""
    for job in store.list_jobs(("done",)):  # newest first
        outputs = job["outputs"]
        name = (
            PROGRAM if PROGRAM in outputs else next((n for n in outputs if n.endswith(GCODE_SUFFIXES)), None)
        )
        if name:
            return job["id"], name
    return None


def stick_name(job_id: str, name: str) -> str:
    """The file's name on the stick: the job id first, so copies of two jobs never collide."""
    return f"{job_id}-{name}"


class UsbExport:
    def __init__(self, exporter, store: Store, job_file: Callable[[str, str], Path], notify: Callable):
        self.exporter = exporter
        self.store = store
        self.job_file = job_file
        self.notify = notify

    def sticks(self) -> list[dict]:
        return [s.to_json() for s in self.exporter.sticks()] if self.exporter is not None else []

    def export(self, job_id: str, name: str, stick: str | None, release: bool) -> dict:
        if self.exporter is None:
            raise DeviceError("usb", "USB export is switched off on this box")
        path = self.job_file(job_id, name)
        return self.exporter.export(path, stick, stick_name(job_id, name), release=release).to_json()

    def latest_gcode(self) -> tuple[str, str] | None:
        return latest_gcode(self.store)

    def export_latest(self) -> dict:
        if self.exporter is None:
            return self.notify(usb_notice("off"))
        latest = self.latest_gcode()
        if latest is None:
            return self.notify(usb_notice("no_gcode"))
        self.notify(usb_notice("copying"), log_it=False)
        try:
            result = self.exporter.export(self.job_file(*latest), None, stick_name(*latest), release=True)
        except NoStick:
            return self.notify(usb_notice("no_stick"))
        except InkSliceError as e:
            return self.notify(usb_notice("failed", problem=e.problem))
        except Exception as e:  # an unexpected bug must still reach the operator
            log.exception("USB export")
            return self.notify(usb_notice("failed", problem=f"{type(e).__name__}: {e}"))
        if not result.safe_to_remove:  # copied and synced, but the unmount failed
            return self.notify(usb_notice("still_mounted", name=result.name, problem=result.unmount_problem))
        return self.notify(usb_notice("copied", name=result.name))
