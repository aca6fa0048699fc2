"""Processing a finished scan: appliance.process.process_scan, by default in
a child process.

Why a child: the height map and the toolpath need far more memory than the
capture (every slice at once), a Pi has 1 GB, and an out-of-memory kill must
take down the processing, not the daemon holding the stage. A child also
stops at once on cancel. Its result comes back as JSON on stdout; an
InkSliceError in it comes back as its one-line text on stderr, exit code 2.

A processor is any callable (scan_folder, out_folder, options, stop_event)
-> {"outputs": [file names], ...}; tests pass `in_process` or a fake. `run` is
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
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from ..errors import Cancelled, InkSliceError

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


def run(processor: Callable, store, job_id: str, settings: dict, stop) -> list[str]:
    """Process job `job_id`'s scan (its folder's scan/) into the job folder with `settings`;
    returns the checked outputs. Raises Cancelled when `stop` was set meanwhile."""
    job_dir = Path(store.job_dir(job_id))
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


def child_process(
    scan_folder,
    out_folder,
    options,
    stop=None,
    poll_s: float = 0.2,
    module: str = "appliance.daemon.processing_child",
) -> dict:
    """`module`: the child's main (processing_child.py, or one that adds to it with the same protocol)."""
    cmd = [sys.executable, "-m", module, str(scan_folder), str(out_folder), json.dumps(options)]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(
            cmd,
            stdout=out,
            stderr=err,
            preexec_fn=_die_with_parent,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        while True:
            # wait4, not wait: it also gives the child's peak memory, which the job records
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                proc.returncode = rc = os.waitstatus_to_exitcode(status)
                break
            if stop is not None and stop.is_set():
                proc.kill()
                proc.wait()
                raise Cancelled()
            time.sleep(poll_s)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    peak_mb = usage.ru_maxrss / 1024  # Linux reports kB
    if rc == 0:
        cpu_s = usage.ru_utime + usage.ru_stime  # on a busy box a far surer figure than the wall time
        return {
            **json.loads(stdout.strip().splitlines()[-1]),
            "peak_rss_mb": round(peak_mb, 1),
            "cpu_s": round(cpu_s, 1),
        }
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
