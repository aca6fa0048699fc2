"""The daemon process: the service, its socket, systemd's notify protocol
and watchdog, and a clean stop on SIGTERM (scan cancelled, hardware safe).

Logs go to stderr, which systemd sends to journald; under journald the
timestamps are left out (the journal has its own).
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
from pathlib import Path

from ..datadir import data_dir
from . import rpc
from .notify import notify, watchdog_interval
from .processing import child_process, in_process
from .service import BenchService

log = logging.getLogger("inkslice.daemon")


def setup_logging(level="INFO"):
    fmt = (
        "%(levelname)s %(name)s: %(message)s"
        if os.environ.get("JOURNAL_STREAM")
        else "%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    logging.basicConfig(level=getattr(logging, level.upper(), logging.INFO), format=fmt, stream=sys.stderr)


def run(factory, data, socket_path=None, processor="child") -> int:
    """`factory`: a hw.base.BenchFactory; `processor`: "child", "inprocess" or a processor
    callable (see processing.py)."""
    data = data_dir(data)
    data.mkdir(parents=True, exist_ok=True)
    socket_path = Path(socket_path or data / "daemon.sock")
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    if not callable(processor):
        processor = child_process if processor == "child" else in_process
    service = BenchService(
        data, factory, processor=processor, disk_free_mb=factory.disk_free_mb, usb=factory.usb()
    )  # the bench button's long press copies to a stick
    server = rpc.serve(service, socket_path)
    if service.interrupted:
        log.warning("interrupted jobs found at start: %s", ", ".join(service.interrupted))
    log.info("ready: data %s, socket %s", data, socket_path)
    notify("READY=1", f"STATUS=idle; data in {data}")
    interval = watchdog_interval() or 1.0
    last_status = None
    try:
        while not stop.wait(interval):
            if service.healthy():
                notify("WATCHDOG=1")  # a hung service stops the pings: systemd restarts us
            st = service.state()
            status = f"STATUS={st['state']} {st['levels_done']}/{st['levels_total']} {st['message']}"
            if status != last_status:
                notify(status)
                last_status = status
    finally:
        notify("STOPPING=1")
        log.info("stopping: cancelling any scan, leaving the hardware safe")
        service.close()
        server.shutdown()
        server.server_close()
        socket_path.unlink(missing_ok=True)
        factory.close()
    return 0
