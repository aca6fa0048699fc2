"""The web's view of the daemon: a facade.Bench (daemon/facade.py), in-process or over
the socket, with the caching and the small shape fixes the routes want.

The routes call only this wrapper. What the daemon offers, and what each method means,
is written once in daemon/facade.py; here are only the web's own concerns: state and
frames cached for a moment, the cache dropped after a command, job records with the
keys the templates read. A call with none of these is not written out here: it goes
through as the daemon answers it (facade.forwards, WebService._forward).
"""

from __future__ import annotations

import contextlib
import copy
import threading
import time
from pathlib import Path

from ..daemon.facade import Bench, forwards, read_only
from ..errors import InkSliceError

ACTIVE = ("homing", "scanning", "processing")
READS = read_only()


class NotOffered(InkSliceError):
    """This box has the feature switched off (the route answers 501), e.g. USB export."""


@forwards("_forward")
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

    def _forward(self, method: str, *args, **kwargs):
        """A facade call the routes take as the daemon answers it (facade.forwards): one that
        only reads goes straight through; any other changes the bench, so the cache drops after it."""
        call = getattr(self.inner, method)
        if method in READS:
            return call(*args, **kwargs)
        with self._command():
            return call(*args, **kwargs)

    @contextlib.contextmanager
    def _command(self):
        """Around a call that changes the bench: its effect (a move, a frame, a job gone) shows at once."""
        try:
            yield
        finally:
            self._drop_cache()

    def usb_sticks(self) -> list[dict]:
        return list(self.inner.usb_sticks())

    def rename_job(self, job_id: str, name: str) -> dict:
        with self._command():
            return self._job(self.inner.rename_job(job_id, name))

    def job_sizes(self) -> dict[str, int]:
        return dict(self.inner.job_sizes())

    @staticmethod
    def _job(j: dict) -> dict:
        j = dict(j)
        if "id" not in j and "job_id" in j:
            j["id"] = j["job_id"]
        j.setdefault("outputs", [])
        j.setdefault("status", "unknown")
        return j
