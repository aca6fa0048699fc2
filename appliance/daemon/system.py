"""The system page's figures: the version, how long the daemon and the box have been up, the
data disk's size and free space, the jobs kept and the webhook's last delivery."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

from .. import __version__


def box_uptime() -> float | None:
    try:
        return float(Path("/proc/uptime").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def figures(data_dir: Path, daemon_started: float, jobs: int, webhook_last: dict | None) -> dict:
    usage = shutil.disk_usage(data_dir)
    return {
        "version": __version__,
        "daemon_started": daemon_started,
        "daemon_uptime_s": round(time.time() - daemon_started, 1),
        "box_uptime_s": box_uptime(),
        "disk": {"path": str(data_dir), "total_bytes": usage.total, "free_bytes": usage.free},
        "jobs": jobs,
        "webhook": webhook_last,
    }
