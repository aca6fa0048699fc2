"""Telling someone away from the bench that a job ended: a JSON POST to the webhook setting.

One message per event, in a thread of its own so a slow or dead receiver never holds a scan:

    {"event": "finished" | "failed" | "needs_attention", "job_id": ..., "name": ..., "status": ...,
     "message": "...", "title": "InkSlice: ...", "box": hostname, "time": unix seconds}

`title` and `message` are plain sentences, so a bridge (ntfy, Home Assistant, a Telegram bot) can
show them as they are. With the webhook_token setting the request carries
`Authorization: Bearer TOKEN`. A failed delivery is logged and kept in last(); it is not retried
(a missed phone buzz is not worth a queue that outlives a restart).
"""

from __future__ import annotations

import json
import logging
import queue
import socket
import threading
import time
import urllib.error
import urllib.request

log = logging.getLogger("inkslice.webhook")
EVENTS = ("finished", "failed", "needs_attention")
TIMEOUT_S = 10.0
TITLES = {"finished": "job finished", "failed": "job failed", "needs_attention": "needs attention"}


def message(event: str, job: dict | None, text: str) -> dict:
    """The JSON body for an event about a job (or the bench, when job is None)."""
    job = job or {}
    name = job.get("name") or job.get("id") or ""
    return {
        "event": event,
        "job_id": job.get("id"),
        "name": job.get("name", ""),
        "status": job.get("status"),
        "message": text,
        "title": f"InkSlice: {TITLES[event]}" + (f" ({name})" if name else ""),
        "box": socket.gethostname(),
        "time": time.time(),
    }


def post(url: str, body: dict, token: str = "", timeout: float = TIMEOUT_S) -> str:
    """POST body as JSON; returns "" when the receiver took it (2xx), else why not."""
    req = urllib.request.Request(
        url,
        data=json.dumps(body).encode(),
        method="POST",
        headers={"Content-Type": "application/json", "User-Agent": "inkslice"},
    )
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return "" if 200 <= r.status < 300 else f"HTTP {r.status}"
    except urllib.error.HTTPError as e:
        return f"HTTP {e.code}"
    except (urllib.error.URLError, OSError, ValueError) as e:
        return str(getattr(e, "reason", e))


class Webhook:
    """Sends events in the background to the address settings() names at the time of the event."""

    def __init__(self, settings):
        self._settings = settings  # callable -> the daemon's settings
        self._queue: queue.Queue = queue.Queue(maxsize=50)
        self._thread: threading.Thread | None = None
        self._last: dict | None = None

    def send(self, event: str, job: dict | None, text: str) -> bool:
        """Queue the event; False when no webhook is set (or the queue is full)."""
        s = self._settings()
        url = s.get("webhook_url", "")
        if not url:
            return False
        try:
            self._queue.put_nowait((url, s.get("webhook_token", ""), message(event, job, text)))
        except queue.Full:
            log.warning("webhook: %d messages waiting, %s dropped", self._queue.qsize(), event)
            return False
        if self._thread is None or not self._thread.is_alive():
            self._thread = threading.Thread(target=self._run, name="inkslice-webhook", daemon=True)
            self._thread.start()
        return True

    def job_ended(self, job: dict | None, state: dict) -> None:
        """A job just finished or failed (a cancel was someone's choice, and commissioning's own
        reference scans are followed on its page): say so."""
        if job is not None and job["params"].get("reference"):
            return
        if state["state"] == "done":
            self.send("finished", job, f"{(job or {}).get('name') or 'the job'} is done")
        else:
            self.send("failed", job, (job or {}).get("reason") or state.get("message") or "the job failed")

    def test(self) -> dict:
        """Send a test message now, to the address set; {"ok", "problem"} (the settings page's button)."""
        s = self._settings()
        if not s.get("webhook_url"):
            return {"ok": False, "problem": "no webhook address is set"}
        body = message("needs_attention", None, "a test message from the settings page: the webhook works")
        body["event"], body["title"] = "test", "InkSlice: webhook test"
        problem = post(s["webhook_url"], body, s.get("webhook_token", ""))
        return {"ok": not problem, "problem": problem}

    def last(self) -> dict | None:
        """The last delivery: {"event", "time", "ok", "problem"}."""
        return self._last

    def _run(self):
        while True:
            url, token, body = self._queue.get()  # a daemon thread: it waits for the next event
            problem = post(url, body, token)
            if problem:
                log.warning("webhook %s to %s: %s", body["event"], url.split("?")[0], problem)
            self._last = {"event": body["event"], "time": body["time"], "ok": not problem, "problem": problem}
