"""The facade over a Unix socket, so the web server can run as its own
service (no device access at all) and tests can drive a daemon subprocess.

One JSON object per line. Request: {"method": NAME, "args": [...],
"kwargs": {...}}. Reply: {"ok": true, "result": ...} or {"ok": false,
"error": {"type": "SettingError", "where": ..., "problem": ...}}.
subscribe() streams {"event": state} lines and ends with {"end": true}.
latest_frame's JPEG travels as base64; job_file returns the path (both
services share the data folder's group).

The methods are those of facade.Bench (METHODS is derived from it). BenchClient
implements the same protocol and raises the same error types, so the web UI cannot
tell it from an in-process BenchService.

Connections: the server reads requests off a connection until the client
closes it, so BenchClient keeps a few connections open and reuses them
(MAX_CONNECTIONS at once; more callers wait their turn) instead of a connect
per call: fifty phones behind the web server then mean a handful of daemon
threads, not fifty. The listen backlog (BACKLOG) is still large, for clients
that connect on their own (tests, scripts, several web workers): the default
of 5 refused connections (EAGAIN) as soon as more than five arrived at once.
"""

from __future__ import annotations

import base64
import json
import logging
import os
import socket
import socketserver
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from .. import errors
from . import facade

log = logging.getLogger("inkslice.rpc")
METHODS = facade.calls()  # what the socket serves: the facade, less subscribe (streamed) and close
BACKLOG = 128  # pending connections the kernel queues (Linux caps it at somaxconn)
MAX_CONNECTIONS = 6  # a BenchClient's open connections (calls in flight) at most
SLOW_CALLS = {
    "calibrate": 180.0,
    "cancel": 45.0,
    "import_scan": 120.0,  # s; homing, a copy,
    "commission": 600.0,  # the search for level zero,
    "export_to_usb": 180.0,
    "test_webhook": 30.0,  # a copy, read back, unmount; a slow receiver
    "home_stage": 90.0,
    "goto_level": 90.0,
    "jog": 60.0,  # the panel's moves
    "repost": 900.0,
}  # a new program from a height map
_ERRORS = {
    c.__name__: c for c in (errors.InkSliceError, errors.SettingError, errors.DeviceError, errors.ScanError)
}


def _encode(method, result):
    if method == "latest_frame" and result is not None:
        jpeg, info = result
        return {"jpeg": base64.b64encode(jpeg).decode(), "info": info}
    if method == "job_file":
        return str(result)
    return result


class _Handler(socketserver.StreamRequestHandler):
    def handle(self):
        try:
            self._serve()
        except (BrokenPipeError, ConnectionResetError):
            pass  # the client went away (e.g. left a subscription early)

    def _serve(self):
        service = self.server.service
        for raw in self.rfile:
            try:
                req = json.loads(raw)
                method, args, kwargs = req["method"], req.get("args", []), req.get("kwargs", {})
            except (ValueError, KeyError, TypeError):
                self._refuse("InkSliceError", "rpc", "malformed request")
                continue
            if method == "subscribe":
                for state in service.subscribe(*args, **kwargs):
                    self._send({"event": state})
                self._send({"end": True})
                continue
            if method not in METHODS:
                self._refuse("InkSliceError", "rpc", f"no method {method!r}")
                continue
            try:
                result = getattr(service, method)(*args, **kwargs)
                self._send({"ok": True, "result": _encode(method, result)})
            except errors.InkSliceError as e:
                kind = next(
                    c.__name__ for c in type(e).__mro__ if c.__name__ in _ERRORS
                )  # NoStick: DeviceError
                self._refuse(kind, e.where, e.problem)
            except Exception as e:
                log.exception("rpc %s", method)
                self._refuse("InkSliceError", "daemon", f"internal error: {type(e).__name__}: {e}")

    def _refuse(self, kind, where, problem):
        """The reply of a call that failed: the error's type name (one of _ERRORS), where, what."""
        self._send({"ok": False, "error": {"type": kind, "where": where, "problem": problem}})

    def _send(self, obj):
        self.wfile.write((json.dumps(obj) + "\n").encode())
        self.wfile.flush()


class _Server(socketserver.ThreadingMixIn, socketserver.UnixStreamServer):
    daemon_threads = True
    request_queue_size = BACKLOG


def serve(service, path) -> _Server:
    """Start serving `service` on the Unix socket `path` in a background thread."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)  # a stale socket from a killed daemon
    server = _Server(str(path), _Handler)
    os.chmod(path, 0o660)  # the daemon's user and group (the web service)
    server.service = service
    threading.Thread(target=server.serve_forever, name="inkslice-rpc", daemon=True).start()
    return server


class _Conn:
    def __init__(self, sock):
        self.sock, self.file = sock, sock.makefile("rwb")

    def close(self):
        for c in (self.file, self.sock):
            try:
                c.close()
            except OSError:
                pass


@facade.forwards("_call")
class BenchClient:
    """The facade (facade.Bench), spoken over the daemon's socket. Thread-safe.

    At most `max_connections` calls are in flight at once, each on a connection
    kept open for the next call; a caller that finds them all busy waits up to
    `timeout`. A kept connection found dead (the daemon restarted) is replaced
    once, transparently, when the request had not reached the daemon or the
    method only reads.
    """

    READ_ONLY = facade.read_only()  # replayed on a fresh connection (facade.reads)

    def __init__(self, path, timeout: float = 30.0, max_connections: int = MAX_CONNECTIONS):
        self.path, self.timeout = str(path), timeout
        self._slots = threading.BoundedSemaphore(max_connections)
        self._idle: list[_Conn] = []
        self._lock = threading.Lock()

    def _connect(self, timeout):
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.settimeout(timeout)
        try:
            s.connect(self.path)
        except OSError as e:
            s.close()
            raise errors.DeviceError(
                f"daemon {self.path}", f"not reachable ({e.strerror or e}): is inkslice-daemon running?"
            ) from None
        return s

    def _exchange(self, conn, request: bytes):
        """(reply line or b"" on EOF, whether the request was surely not delivered)."""
        try:
            conn.file.write(request)
            conn.file.flush()
        except (BrokenPipeError, ConnectionResetError):
            return b"", True
        try:
            return conn.file.readline(), False
        except ConnectionResetError:
            return b"", False

    def _call(self, method, *args, **kwargs):
        request = (json.dumps({"method": method, "args": args, "kwargs": kwargs}) + "\n").encode()
        t0 = time.monotonic()
        timeout = max(self.timeout, SLOW_CALLS.get(method, 0.0))
        if not self._slots.acquire(timeout=self.timeout):
            raise errors.DeviceError(
                f"daemon {self.path}",
                f"no free connection in {self.timeout:.0f} s (the daemon is not answering)",
            )
        try:
            with self._lock:
                conn = self._idle.pop() if self._idle else None
            reused = conn is not None
            if conn is None:
                conn = _Conn(self._connect(self.timeout))
            conn.sock.settimeout(timeout)
            try:
                line, undelivered = self._exchange(conn, request)
                if not line and reused and (undelivered or method in self.READ_ONLY):
                    conn.close()  # a connection from before a daemon restart
                    conn = _Conn(self._connect(max(1.0, self.timeout - (time.monotonic() - t0))))
                    conn.sock.settimeout(timeout)
                    line, _ = self._exchange(conn, request)
            except TimeoutError:
                conn.close()  # a late reply would answer the next call: drop it
                raise errors.DeviceError(
                    f"daemon {self.path}", f"no answer to {method} in {timeout:.0f} s"
                ) from None
            except BaseException:
                conn.close()
                raise
            if not line:
                conn.close()
                raise errors.DeviceError(f"daemon {self.path}", "closed the connection without a reply")
            with self._lock:
                self._idle.append(conn)
        finally:
            self._slots.release()
        reply = json.loads(line)
        if not reply["ok"]:
            e = reply["error"]
            raise _ERRORS.get(e["type"], errors.InkSliceError)(e["where"], e["problem"])
        return reply["result"]

    # Every other facade call is sent as it is (facade.forwards); these encode what JSON cannot carry.
    def job_file(self, job_id: str, name: str) -> Path:
        return Path(self._call("job_file", job_id, name))

    def import_scan(self, folder: str | Path) -> str:
        return self._call("import_scan", str(folder))

    def latest_frame(self) -> tuple[bytes, dict] | None:
        r = self._call("latest_frame")
        return None if r is None else (base64.b64decode(r["jpeg"]), r["info"])

    def subscribe(self, timeout: float = 30.0) -> Iterator[dict]:
        with self._connect(timeout + 10) as s, s.makefile("rwb") as f:
            f.write((json.dumps({"method": "subscribe", "args": [timeout]}) + "\n").encode())
            f.flush()
            for line in f:
                msg = json.loads(line)
                if msg.get("end"):
                    return
                yield msg["event"]

    def close(self) -> None:
        with self._lock:
            idle, self._idle = self._idle, []
        for conn in idle:
            conn.close()
