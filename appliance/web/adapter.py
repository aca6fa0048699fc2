"""The web's view of the daemon: a facade.Bench (daemon/facade.py), in-process or over
the socket, with the caching and the small shape fixes the routes want.

The routes call only this wrapper. What the daemon offers, and what each method means,
is written once in daemon/facade.py; here are only the web's own concerns: state and
frames cached for a moment, the cache dropped after a command, job records with the
keys the templates read.
"""

from __future__ import annotations

import contextlib
import copy
import threading
import time
from pathlib import Path

from ..daemon.facade import Bench
from ..errors import InkSliceError

ACTIVE = ("homing", "scanning", "processing")


class NotOffered(InkSliceError):
    """This box has the feature switched off (the route answers 501), e.g. USB export."""


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

    def __init__(self, service: Bench, clock=time.monotonic):
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
        with self._command():
            return self.inner.start_scan(params)

    def cancel(self) -> None:
        with self._command():
            return self.inner.cancel()

    def resume(self, job_id: str) -> str:
        with self._command():
            return self.inner.resume(job_id)

    def jobs(self) -> list[dict]:
        return [self._job(j) for j in self.inner.jobs()]

    def job(self, job_id: str) -> dict:
        return self._job(self.inner.job(job_id))

    def job_file(self, job_id: str, name: str) -> Path:
        return Path(self.inner.job_file(job_id, name))

    def latest_frame(self) -> tuple[bytes, dict] | None:
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
        with self._command():
            return dict(self.inner.update_settings(changes))

    @contextlib.contextmanager
    def _command(self):
        """Around a call that changes the bench: its effect (a move, a frame, a job gone) shows at once."""
        try:
            yield
        finally:
            self._drop_cache()

    def live_heightmap(self) -> dict | None:
        return self.inner.live_heightmap()

    def calibration(self) -> dict:
        return self.inner.calibration()

    def calibrate(self, step: str) -> dict:
        with self._command():
            return self.inner.calibrate(step)

    def commissioning(self) -> dict:
        return self.inner.commissioning()

    def commission(self, step: str, action: str, values: dict | None = None) -> dict:
        with self._command():  # a step changes the state message (and may start a scan)
            return self.inner.commission(step, action, values)

    def export_commissioning(self) -> dict:
        return self.inner.export_commissioning()

    def import_commissioning(self, doc: dict) -> dict:
        with self._command():
            return self.inner.import_commissioning(doc)

    def ink_changed(self) -> dict:
        return self.inner.ink_changed()

    def import_scan(self, folder: Path) -> str:
        with self._command():  # the import starts processing: show it at once
            return self.inner.import_scan(folder)

    def usb_sticks(self) -> list[dict]:
        return list(self.inner.usb_sticks())

    def export_to_usb(self, job_id: str, name: str, stick: str | None) -> dict:
        return self.inner.export_to_usb(job_id, name, stick)

    def backup(self) -> dict:
        return self.inner.backup()

    def restore(self, doc: dict) -> dict:
        with self._command():
            return self.inner.restore(doc)

    def system(self) -> dict:
        return self.inner.system()

    def test_webhook(self) -> dict:
        return self.inner.test_webhook()

    def preview(self) -> dict:
        with self._command():
            return self.inner.preview()

    def home_stage(self) -> dict:
        with self._command():
            return self.inner.home_stage()

    def jog(self, mm: float) -> dict:
        with self._command():
            return self.inner.jog(mm)

    def goto_level(self, level_mm: float) -> dict:
        with self._command():
            return self.inner.goto_level(level_mm)

    def rename_job(self, job_id: str, name: str) -> dict:
        with self._command():
            return self._job(self.inner.rename_job(job_id, name))

    def delete_job(self, job_id: str) -> None:
        with self._command():
            self.inner.delete_job(job_id)

    def reprocess(self, job_id: str, changes: dict) -> str:
        with self._command():
            return self.inner.reprocess(job_id, changes)

    def repost(self, job_id: str, options: dict) -> list[str]:
        with self._command():
            return self.inner.repost(job_id, options)

    def job_sizes(self) -> dict[str, int]:
        return dict(self.inner.job_sizes())

    def events(self, job_id: str | None = None, limit: int = 200) -> list[dict]:
        return self.inner.events(job_id, limit)

    @staticmethod
    def _job(j: dict) -> dict:
        j = dict(j)
        if "id" not in j and "job_id" in j:
            j["id"] = j["job_id"]
        j.setdefault("outputs", [])
        j.setdefault("status", "unknown")
        return j
