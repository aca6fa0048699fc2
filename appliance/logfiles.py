"""The daemon's and the web's logs, also kept as files in the data folder for the system page.

journald has them too on the box, but the web service may not read the journal, and a support
bundle wants them as plain text. Each process appends to DATA/logs/NAME.log, rotated at
MAX_BYTES (one older file kept), so the last LINES lines are always at hand.
"""

from __future__ import annotations

import logging
import logging.handlers
from collections import deque
from pathlib import Path

NAMES = ("daemon", "web")
MAX_BYTES = 1024 * 1024
LINES = 1000
FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def path(data_dir, name: str) -> Path:
    return Path(data_dir) / "logs" / f"{name}.log"


def log_to_file(data_dir, name: str, level=logging.INFO) -> Path | None:
    """Also write this process's log records to DATA/logs/NAME.log; None when that folder is not ours."""
    p = path(data_dir, name)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        handler = logging.handlers.RotatingFileHandler(p, maxBytes=MAX_BYTES, backupCount=1, encoding="utf-8")
    except OSError as e:
        logging.getLogger("inkslice").warning("no log file %s: %s", p, e)
        return None
    handler.setFormatter(logging.Formatter(FORMAT))
    root = logging.getLogger()
    root.addHandler(handler)
    if root.level > level or root.level == logging.NOTSET:
        root.setLevel(level)
    return p


def tail(data_dir, name: str, lines: int = LINES) -> str:
    """The last `lines` lines of NAME's log (the rotated file first when the current one is short)."""
    p = path(data_dir, name)
    last: deque[str] = deque(maxlen=lines)
    for f in (p.with_name(p.name + ".1"), p):
        try:
            with open(f, encoding="utf-8", errors="replace") as fh:
                last.extend(fh)
        except OSError:
            continue
    return "".join(last)
