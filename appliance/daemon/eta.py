"""How long a job will take, learned from this box's past jobs: scanning plus processing.

Why learned: a level's time (move, settle, capture, find the part) and processing's time (the
height map and the toolpath, in a child) depend on this box's stage, camera and CPU. The first
estimate used to leave processing out ("about 0 s left" for a minute and more) and to guess the
level time before a level was done (2.5 x too high). Each finished job leaves one line in
DATA/timings.json: its levels, its scanning seconds and its processing seconds. The estimate is
then, per level, the median over the last RECENT jobs (a median: one job slowed by a busy CPU
does not move it), times the levels of this job.

During a scan the daemon's eta_s = levels left x (this scan's own recent level time, or the
learned one before a level is done) + the learned processing time; when processing starts, the
learned processing time (the web's smoother counts it down with the clock). A box with no finished job yet knows no
processing time: eta_processing_s is None and the estimate covers the scan only.
"""

from __future__ import annotations

import json
import statistics
import threading
import time
from pathlib import Path

from ..atomicio import write_text

RECENT = 10
FILE = "timings.json"


class JobTimes:
    def __init__(self, data_dir):
        self.path = Path(data_dir) / FILE
        self._lock = threading.Lock()
        self._jobs = self._load()

    def _load(self) -> list[dict]:
        try:
            doc = json.loads(self.path.read_text())
            jobs = doc.get("jobs", []) if isinstance(doc, dict) else []
        except (OSError, ValueError):
            return []
        return [
            j
            for j in jobs
            if isinstance(j, dict)
            and _positive(j.get("levels"))
            and _positive(j.get("scan_s"), zero=True)
            and _positive(j.get("process_s"), zero=True)
        ]

    def record(self, job_id: str, levels: int, scan_s: float, process_s: float) -> None:
        """One finished job's times (a job that failed or was cancelled teaches nothing)."""
        if not levels or scan_s < 0 or process_s < 0:
            return
        with self._lock:
            self._jobs = (
                self._jobs
                + [
                    {
                        "job": job_id,
                        "levels": int(levels),
                        "scan_s": round(scan_s, 2),
                        "process_s": round(process_s, 2),
                    }
                ]
            )[-50:]
            try:
                write_text(self.path, json.dumps({"jobs": self._jobs}, indent=1) + "\n")
            except OSError:
                pass  # an estimate is worth no failed job

    def per_level_s(self) -> float | None:
        """Scanning seconds per level, learned; None before the first finished job."""
        with self._lock:
            recent = self._jobs[-RECENT:]
        return statistics.median(j["scan_s"] / j["levels"] for j in recent) if recent else None

    def processing_s(self, levels: int) -> float | None:
        """Expected processing seconds for a scan of `levels` levels; None before the first finished job."""
        with self._lock:
            recent = self._jobs[-RECENT:]
        if not recent or not levels:
            return None
        return statistics.median(j["process_s"] / j["levels"] for j in recent) * levels

    def count(self) -> int:
        with self._lock:
            return len(self._jobs)


def _positive(v, zero=False) -> bool:
    return isinstance(v, (int, float)) and (v >= 0 if zero else v > 0)


class JobClock:
    """A scan's ETA, scanning plus processing (eta.py), and its times once it ends done."""

    def __init__(self, times: JobTimes, fresh: bool, clock=time.monotonic):
        self.times, self.fresh, self.clock = times, fresh, clock
        self.t0 = clock()
        self.t_proc = None
        self.per_level = times.per_level_s()

    def eta(self, state: dict, changes: dict) -> dict:
        """`changes` with eta_s (and eta_processing_s) made to cover what is left of the whole job."""
        out = dict(changes)
        total, done = int(state.get("levels_total") or 0), int(state.get("levels_done") or 0)
        proc = self.times.processing_s(total)
        if state.get("state") == "processing":
            if self.t_proc is None:
                self.t_proc = self.clock()
                out["eta_s"] = None if proc is None else round(proc, 1)
                out["eta_processing_s"] = out["eta_s"]
            return out
        if "eta_s" in changes or "levels_done" in changes or "state" in changes:
            scan = changes.get("eta_s")  # the runner's: levels left x its recent level time
            if scan is None and self.per_level is not None:
                scan = self.per_level * max(total - done, 0)
            out["eta_s"] = None if scan is None else round(scan + (proc or 0.0), 1)
            out["eta_processing_s"] = None if proc is None else round(proc, 1)
        return out

    def finished(self, job_id: str, levels: int):
        if self.fresh and self.t_proc is not None:  # a resumed scan's times are only part of one
            now = self.clock()
            self.times.record(job_id, levels, self.t_proc - self.t0, now - self.t_proc)
