"""Processing a finished scan: appliance.process.process_scan, by default in
a child process.

Why a child: the height map and the toolpath need far more memory than the
capture (every slice at once), a Pi has 1 GB, and an out-of-memory kill must
take down the processing, not the daemon holding the stage. A child also
stops at once on cancel. Its result comes back as JSON on stdout; an
InkSliceError in it comes back as its one-line text on stderr, exit code 2.

A processor is any callable (scan_folder, out_folder, options, stop_event)
-> {"outputs": [file names], ...}; tests pass `in_process` or a fake. One that
can also start before the capture ends has `follow` (`Follows`): the runner then
starts it with the capture, and it reads each frame's waterline as the frame
lands (`EarlyChild`), so the result is ready sooner after the last frame. `run` is
the one way a job's scan is processed, for a captured scan (runner.py) and an
imported one (service.py) alike: the job's settings become the processor's
options (`options_for`), the outputs are checked, the peak memory noted.

The job folder is the output folder: process_scan replaces it whole, keeping
only what the daemon itself put there (JOB_OWN: the scan; a processor may add to
`keep`, as the simulated bench does for its truth file),
so no output of an earlier run is left beside the new ones. A job ends `done`
only with its finishing program (`checked_outputs`); otherwise `failed`.

Words: "processing" is this step, a scan folder to a job's outputs. Its work is
`inkslice process`'s (appliance/process.py); a "process" here is the operating
system's: the daemon's own (`in_process`) or a child (`child_process`, whose main
is processing_child.py).
"""

from __future__ import annotations

import ctypes
import gc
import json
import logging
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol, runtime_checkable

from ..errors import Cancelled, InkSliceError

log = logging.getLogger("inkslice.processing")

JOB_OWN = ("scan",)  # what a job folder holds besides the outputs
PROGRAM = "toolpath.gcode"


def checked_outputs(result: dict, job_dir) -> list[str]:
    """The outputs a processor reported, if they include the finishing program on disk
    (a processor that measures, not mills, says so with "makes_program": False)."""
    outputs = sorted(result.get("outputs", []))
    if result.get("makes_program", True) is False:
        return outputs
    if PROGRAM not in outputs or not (Path(job_dir) / PROGRAM).is_file():
        raise InkSliceError(
            "processing", f"no finishing program ({PROGRAM}) was written; the scan is kept, process it again"
        )
    return outputs


def options_for(settings: dict) -> dict:
    """The job's settings (settings.full) as process_scan's keyword arguments."""
    options = {
        "grid_n": int(settings["grid"]),
        "cam_options": {
            "cutter": f"{settings['cutter_type']}{settings['cutter_diameter_mm']:g}",
            "dialect": settings["dialect"],
            "scallop": float(settings["scallop_mm"]),
        },
        "keep": list(JOB_OWN),
    }
    for key in ("pipeline", "method"):  # "" leaves process_scan's own default
        if settings.get(key):
            options[key] = settings[key]
    return options


def run(processor: Callable, store, job_id: str, settings: dict, stop, early=None) -> list[str]:
    """Process job `job_id`'s scan (its folder's scan/) into the job folder with `settings`
    (by `early`, the child that followed the capture, if there is one); returns the checked
    outputs. Raises Cancelled when `stop` was set meanwhile."""
    job_dir = Path(store.job_dir(job_id))
    if early is not None:
        result = early.result(stop)
    else:
        result = processor(job_dir / "scan", job_dir, options_for(settings), stop)
    if stop is not None and stop.is_set():
        raise Cancelled()
    if "peak_rss_mb" in result:
        # [seconds, the child's peak MB when the phase ended]: where the time and the memory went
        phases = ", ".join(f"{k} {s:g} s (to {mb} MB)" for k, (s, mb) in result.get("phases", {}).items())
        store.event(
            job_id,
            "processed",
            f"processing peak memory {result['peak_rss_mb']} MB"
            + (f", {result['cpu_s']:g} s CPU" if "cpu_s" in result else "")
            + (f"; {phases}" if phases else ""),
        )
    return checked_outputs(result, job_dir)


def in_process(scan_folder, out_folder, options, stop=None) -> dict:
    # imported here, not above: the processing code (scipy, the CAM) costs the daemon
    # some 40 MB it does not need when it processes in a child
    from ..process import process_scan

    return process_scan(scan_folder, out_folder, **options)


def release_freed_memory():
    """Hand the heap the capture freed back to the kernel before the child starts.

    Frames and their temporaries are freed after each one is saved, but glibc keeps the
    freed heap for reuse: the daemon stayed at its capture's peak (185 MB against 100
    idle on the demo's scan) all through the processing, while the child needed the room.
    """
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: nothing to trim
        pass


def _die_with_parent():
    """In the child, before exec: ask the kernel to SIGKILL it when the daemon dies,
    so a kill -9 of the daemon cannot leave an orphan writing into the job folder."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


CHILD = "appliance.daemon.processing_child"


def child_process(
    scan_folder, out_folder, options, stop=None, poll_s: float = 0.2, module: str = CHILD
) -> dict:
    """`module`: the child's main (processing_child.py, or one that adds to it with the same protocol)."""
    with _Child(module, scan_folder, out_folder, options) as child:
        return child.result(stop, poll_s)


def _pidfd(pid: int) -> int | None:
    """A descriptor that becomes readable when process `pid` ends (Linux 5.3), or None."""
    try:
        return os.pidfd_open(pid)
    except (AttributeError, OSError):
        return None


class _Child:
    """A processing child: its process and the files its stdout and stderr go to."""

    def __init__(self, module, scan_folder, out_folder, options, follow=False):
        cmd = [sys.executable, "-m", module, str(scan_folder), str(out_folder), json.dumps(options)]
        self.out, self.err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            cmd + (["--follow"] if follow else []),
            stdin=subprocess.PIPE if follow else subprocess.DEVNULL,
            stdout=self.out,
            stderr=self.err,
            preexec_fn=_die_with_parent,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Kill it if it still runs (a cancel, a failed scan), and drop its files."""
        if self.proc.returncode is None:
            self.proc.kill()
            self.proc.wait()
        self.out.close()
        self.err.close()

    def result(self, stop, poll_s) -> dict:
        # the child's end wakes us at once (a pidfd is readable when it ends: polled every
        # 0.2 s, the result came 0.1 s late on average); `stop` is looked at every poll_s
        ended = _pidfd(self.proc.pid)
        try:
            while True:
                # wait4, not wait: it also gives the child's peak memory, which the job records
                pid, status, usage = os.wait4(self.proc.pid, os.WNOHANG)
                if pid:
                    self.proc.returncode = rc = os.waitstatus_to_exitcode(status)
                    break
                if stop is not None and stop.is_set():
                    self.close()
                    raise Cancelled()
                if ended is None:
                    time.sleep(poll_s)
                else:
                    select.select([ended], [], [], poll_s)
        finally:
            if ended is not None:
                os.close(ended)
        self.out.seek(0)
        self.err.seek(0)
        stdout, stderr = self.out.read().decode(errors="replace"), self.err.read().decode(errors="replace")
        return _outcome(rc, usage, stdout, stderr)


class EarlyChild(_Child):
    """The processing child started when the capture starts (runner.py): it imports the
    processing code and reads each frame's waterline as the frame lands, so the result is
    ready sooner after the last frame (processing_child.py --follow). `result` tells it the
    capture is over; `close` (any other end of the scan) ends it."""

    def __init__(self, scan_folder, out_folder, options, module: str = CHILD):
        super().__init__(module, scan_folder, out_folder, options, follow=True)
        self.args = (scan_folder, out_folder, options)
        self.module = module

    def result(self, stop, poll_s=0.2) -> dict:
        if self.proc.poll() is not None:
            # it ended while following (killed for memory, say): a child as before does it all
            log.warning(
                "the processing child that followed the scan ended (%s): starting another",
                self.proc.returncode,
            )
            return child_process(*self.args, stop, poll_s, self.module)
        try:
            self.proc.stdin.write(b"go\n")
            self.proc.stdin.close()
        except BrokenPipeError:  # it has ended already: its exit code says why
            pass
        return super().result(stop, poll_s)

    def close(self):
        if self.proc.stdin and not self.proc.stdin.closed:
            try:
                self.proc.stdin.close()
            except BrokenPipeError:
                pass
        super().close()


@runtime_checkable
class Follows(Protocol):
    """A processor that can start before the capture ends (`child_process` can; `in_process`
    and a test's fakes cannot, and run when the capture is over)."""

    def follow(self, scan_folder, out_folder, options) -> EarlyChild: ...


child_process.follow = lambda scan_folder, out_folder, options: EarlyChild(  # type: ignore[attr-defined]
    scan_folder, out_folder, options
)


def start_early(processor, scan_folder, out_folder, settings) -> EarlyChild | None:
    """The child that follows the capture, for a processor that can."""
    if not isinstance(processor, Follows):
        return None
    return processor.follow(scan_folder, out_folder, options_for(settings))


def _outcome(rc, usage, stdout, stderr) -> dict:
    # (ru_maxrss counts what the daemon held when it forked the child: the child's own peak
    # is the one it reports, progress.peak_mb)
    peak_mb = usage.ru_maxrss / 1024  # Linux reports kB
    if rc == 0:
        cpu_s = usage.ru_utime + usage.ru_stime  # on a busy box a far surer figure than the wall time
        result = json.loads(stdout.strip().splitlines()[-1])
        return {**result, "peak_rss_mb": result.pop("peak_mb", round(peak_mb, 1)), "cpu_s": round(cpu_s, 1)}
    if rc == 2 and stderr.strip():
        where, _, problem = stderr.strip().splitlines()[-1].partition(": ")
        raise InkSliceError(where or "processing", problem or stderr.strip())
    if rc < 0:
        raise InkSliceError(
            "processing",
            f"the processing child was killed by signal {-rc} after reaching "
            f"{peak_mb:.0f} MB (out of memory?); the scan is kept, process it again",
        )
    tail = stderr.strip().splitlines()[-1] if stderr.strip() else "no message"
    raise InkSliceError("processing", f"failed with exit code {rc}: {tail}")
