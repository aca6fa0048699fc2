"""The one place that knows how the daemon's BenchService is spelled.

The routes call only this wrapper. It passes the agreed facade through
(state, start_scan, cancel, resume, jobs, job, job_file, latest_frame,
settings, update_settings) and turns the optional extras into "not offered"
when a service lacks them, so the UI can hide a feature instead of failing:

  live_heightmap()       the height map so far (dashboard)
  calibration(), calibrate(step)   guided calibration
  commissioning(), commission(step, action, values), export_commissioning(),
  import_commissioning(doc), ink_changed()   commissioning (daemon/commissioning.py)
  import_scan(folder)    an uploaded scan folder becomes a job
  usb_sticks(), export_to_usb(job_id, name, stick)   the daemon copies a job's file to a stick
  backup(), restore(doc), system()   the system page (daemon/backup.py, BenchService.system)
  preview(), home_stage(), jog(mm), goto_level(level_mm)   the bench page's machine panel
  rename_job(job_id, name), delete_job(job_id), reprocess(job_id, changes), job_sizes()   the job manager

If the daemon's real API drifts from the facade, the translation goes here
and nowhere else.
"""

from __future__ import annotations

import copy
import threading
import time
from pathlib import Path

from ..errors import InkSliceError

ACTIVE = ("homing", "scanning", "processing")


class NotOffered(InkSliceError):
    """The service has no such feature (the route answers 501)."""


class WebService:
    """`state()` and `latest_frame()` are cached for a moment (STATE_TTL_S, FRAME_TTL_S).

    Why: fifty phones polling once a second, plus every live-view stream checking
    for a new frame four times a second, would otherwise each be a call into the
    daemon (over its socket: a connect, JSON, and for frames a base64 JPEG), all
    competing with the scan for the Pi's two cores. A tenth of a second of
    staleness is invisible on a screen; any command (start, cancel, resume,
    settings) drops the cache so its effect shows at once.
    """

    STATE_TTL_S = 0.1
    FRAME_TTL_S = 0.2

    def __init__(self, service, clock=time.monotonic):
        self.inner = service
        self.clock = clock
        self._cache: dict[str, tuple[float, object]] = {}
        self._cache_lock = threading.Lock()
        self._fetch_locks = {"state": threading.Lock(), "frame": threading.Lock()}

    def _cached(self, key, ttl, fetch):
        # Single flight: when the entry is stale, one request thread fetches while the others
        # wait for it, so a burst of 50 polls is still one call into the daemon.
        with self._fetch_locks.setdefault(key, threading.Lock()):
            now = self.clock()
            with self._cache_lock:
                hit = self._cache.get(key)
                if hit is not None and now - hit[0] < ttl:
                    return hit[1]
            value = fetch()
            with self._cache_lock:
                self._cache[key] = (self.clock(), value)
            return value

    def _drop_cache(self):
        with self._cache_lock:
            self._cache.clear()

    # -- the agreed facade -----------------------------------------------------------
    def state(self) -> dict:
        return copy.deepcopy(self._cached("state", self.STATE_TTL_S, self._fetch_state))

    def _fetch_state(self) -> dict:
        st = dict(self.inner.state())
        st.setdefault("hardware", {})
        for key in ("job_id", "level_mm", "eta_s", "message", "notice"):
            st.setdefault(key, None)
        if isinstance(st["notice"], dict) and isinstance(st["notice"].get("time"), (int, float)):
            # the age from the box's own clock: a phone's clock may be minutes off
            st["notice"] = {**st["notice"], "age_s": round(max(0.0, time.time() - st["notice"]["time"]), 1)}
        st.setdefault("levels_done", 0)
        st.setdefault("levels_total", 0)
        return st

    def start_scan(self, params: dict) -> str:
        try:
            return self.inner.start_scan(params)
        finally:
            self._drop_cache()

    def cancel(self):
        try:
            return self.inner.cancel()
        finally:
            self._drop_cache()

    def resume(self, job_id: str) -> str:
        try:
            return self.inner.resume(job_id)
        finally:
            self._drop_cache()

    def jobs(self) -> list[dict]:
        return [self._job(j) for j in self.inner.jobs()]

    def job(self, job_id: str) -> dict:
        return self._job(self.inner.job(job_id))

    def job_file(self, job_id: str, name: str) -> Path:
        return Path(self.inner.job_file(job_id, name))

    def latest_frame(self):
        return self._cached("frame", self.FRAME_TTL_S, self._fetch_frame)

    def _fetch_frame(self):
        got = self.inner.latest_frame()
        if got is None:
            return None
        data, meta = got
        return bytes(data), dict(meta or {})

    def settings(self) -> dict:
        return dict(self.inner.settings())

    def update_settings(self, changes: dict) -> dict:
        try:
            return dict(self.inner.update_settings(changes))
        finally:
            self._drop_cache()

    # -- optional extras ---------------------------------------------------------------
    def offers(self, name: str) -> bool:
        return callable(getattr(self.inner, name, None))

    def _optional(self, name, *args):
        fn = getattr(self.inner, name, None)
        if not callable(fn):
            raise NotOffered("bench", f"this bench service does not offer {name}")
        return fn(*args)

    def live_heightmap(self):
        return self._optional("live_heightmap")

    def calibration(self):
        return self._optional("calibration")

    def calibrate(self, step: str):
        try:
            return self._optional("calibrate", step)
        finally:
            self._drop_cache()

    def commissioning(self):
        return self._optional("commissioning")

    def commission(self, step: str, action: str, values: dict | None = None):
        try:
            return self._optional("commission", step, action, values)
        finally:
            self._drop_cache()  # a step changes the state message (and may start a scan)

    def export_commissioning(self):
        return self._optional("export_commissioning")

    def import_commissioning(self, doc: dict):
        try:
            return self._optional("import_commissioning", doc)
        finally:
            self._drop_cache()

    def ink_changed(self):
        return self._optional("ink_changed")

    def import_scan(self, folder: Path) -> str:
        try:
            return self._optional("import_scan", folder)
        finally:
            self._drop_cache()  # the import starts processing: show it at once

    def usb_sticks(self) -> list[dict]:
        return list(self._optional("usb_sticks"))

    def export_to_usb(self, job_id: str, name: str, stick: str | None) -> dict:
        return self._optional("export_to_usb", job_id, name, stick)

    def backup(self) -> dict:
        return self._optional("backup")

    def restore(self, doc: dict) -> dict:
        try:
            return self._optional("restore", doc)
        finally:
            self._drop_cache()

    def system(self) -> dict:
        return self._optional("system")

    def test_webhook(self) -> dict:
        return self._optional("test_webhook")

    def _command(self, name, *args):
        try:
            return self._optional(name, *args)
        finally:
            self._drop_cache()  # its effect (a move, a new frame, a job gone) shows at once

    def preview(self):
        return self._command("preview")

    def home_stage(self):
        return self._command("home_stage")

    def jog(self, mm: float):
        return self._command("jog", mm)

    def goto_level(self, level_mm: float):
        return self._command("goto_level", level_mm)

    def rename_job(self, job_id: str, name: str) -> dict:
        return self._job(self._command("rename_job", job_id, name))

    def delete_job(self, job_id: str):
        return self._command("delete_job", job_id)

    def reprocess(self, job_id: str, changes: dict) -> str:
        return self._command("reprocess", job_id, changes)

    def repost(self, job_id: str, options: dict) -> list:
        return self._command("repost", job_id, options)

    def job_sizes(self) -> dict:
        return dict(self._optional("job_sizes")) if self.offers("job_sizes") else {}

    def events(self, job_id=None, limit=200) -> list[dict]:
        return self._optional("events", job_id, limit)

    @staticmethod
    def _job(j: dict) -> dict:
        j = dict(j)
        if "id" not in j and "job_id" in j:
            j["id"] = j["job_id"]
        j.setdefault("outputs", [])
        j.setdefault("status", "unknown")
        return j
