"""Serve the web UI with waitress: the production server (`inkslice serve`, which the
inkslice-web unit runs) and what `make demo` calls.

    from appliance.web.server import serve
    serve(bench_service, data_dir="var/demo")          # blocks; Ctrl-C stops it

prints the URL and, on first run, the admin password (also left for the
daemon to show on the bench's display, see daemon/firstrun.py). start() does
the same in a background thread and returns a handle with .url, .password and
.stop(), for tests and benches.
"""

from __future__ import annotations

import tempfile
import threading
from pathlib import Path

from waitress.server import create_server

from . import limits
from .app import create_app

# waitress's default of 4 threads is too few once phones hold Server-Sent-Events
# streams open (one thread each); 24 threads cost a few MB on the Pi.
THREADS = 24


class Running:
    def __init__(self, server, app, thread=None):
        self.server, self.app, self.thread = server, app, thread
        host, port = server.effective_host, server.effective_port
        self.url = f"http://{host}:{port}"
        self.password = app.config["FIRST_RUN_PASSWORD"]

    def stop(self):
        self.server.close()
        if self.thread:
            self.thread.join(timeout=5)


def _server(service, data_dir, host, port, threads, config):
    cfg = {"data_dir": str(data_dir)}
    cfg.update(config or {})
    app = create_app(service, cfg)
    cfg = app.extensions["inkslice"]["config"]
    server = create_server(
        app, host=host, port=port, **limits.server_settings(cfg["max_upload_bytes"], threads)
    )
    limits.gate_server(
        server,
        app.extensions["inkslice"]["may_send_body"],
        per_address=None if cfg.get("trusted_proxy") else limits.PER_ADDRESS,
    )
    return server, app


def banner(run: Running) -> str:
    lines = [f"InkSlice web UI: {run.url}/"]
    if run.server.effective_host in ("0.0.0.0", "::"):  # on every address: say which a phone uses
        import socket

        from ..daemon.service import lan_address

        port = run.server.effective_port
        lines.append(
            f"From a phone on the same network: http://{lan_address()}:{port}/ "
            f"(or http://{socket.gethostname()}.local:{port}/ where mDNS works)"
        )
    if run.password:
        lines.append(f"First-run admin password: {run.password}   (change it under Settings)")
    else:
        lines.append("Admin password: already set (forgot it? delete DATA/web/admin.json and restart)")
    return "\n".join(lines)


def _say(text):
    print(text, flush=True)  # flushed: a supervisor or a test reads it through a pipe


def serve(service, data_dir, host="127.0.0.1", port=8080, threads=THREADS, config=None, out=_say):
    """Run until interrupted."""
    limits.raise_open_files()
    # waitress spools a logged-in upload's body to a temporary file before the app runs: keep
    # it on the data disk (a RAM /tmp would charge it to the web's memory limit)
    spool = Path(data_dir) / "web" / "uploads"
    spool.mkdir(parents=True, exist_ok=True)
    tempfile.tempdir = str(spool)
    server, app = _server(service, data_dir, host, port, threads, config)
    run = Running(server, app)
    out(banner(run))
    try:
        server.run()
    finally:
        server.close()


def start(service, data_dir, host="127.0.0.1", port=0, threads=THREADS, config=None) -> Running:
    """Serve in a daemon thread (port 0: any free port); returns at once."""
    limits.raise_open_files()
    server, app = _server(service, data_dir, host, port, threads, config)
    t = threading.Thread(target=server.run, daemon=True, name="inkslice-web")
    t.start()
    return Running(server, app, t)
