"""What the benches that run the daemon as a subprocess (daemon.py, keepup.py) share:
a scratch folder, the daemon started in it, and its memory as the kernel counts it.

The folder is a real one (not a TemporaryDirectory) because the daemon's data, socket
and log must outlive a crash of the daemon, and --keep leaves it to look into when a
figure looks wrong.
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from appliance.daemon.rpc import BenchClient  # noqa: E402
from appliance.errors import DeviceError  # noqa: E402


@contextlib.contextmanager
def bench_tmp(keep: bool, prefix: str) -> Iterator[Path]:
    """A fresh folder named `prefix`...; at the end removed, or, with `keep`, its path printed."""
    tmp = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        yield tmp
    finally:
        if keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


def start_daemon(tmp: Path, *flags: str, wait_s: float = 120.0) -> tuple[subprocess.Popen, BenchClient]:
    """`inkslice daemon FLAGS` with its data, socket and log in `tmp`, once it answers on the
    socket: (the process, a client). The bench exits with the log's end when it does not."""
    sock = tmp / "d.sock"
    cmd = [sys.executable, "-m", "appliance.cli", "daemon", *flags]
    cmd += ["--data", str(tmp / "data"), "--socket", str(sock)]
    with open(tmp / "daemon.log", "wb") as log:  # the daemon writes to its own copy
        proc = subprocess.Popen(cmd, stdout=log, stderr=log, cwd=REPO)
    client = BenchClient(sock)
    deadline = time.monotonic() + wait_s
    while True:
        try:
            client.state()
            return proc, client
        except DeviceError:
            if proc.poll() is not None or time.monotonic() > deadline:
                sys.exit(f"daemon did not start: {(tmp / 'daemon.log').read_text()[-2000:]}")
            time.sleep(0.1)


def tree_pids(pid: int) -> list[int]:
    """pid and every process below it (the daemon, its processing child, that child's workers)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        try:
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except OSError:  # it ended meanwhile
            pass
    return out


def tree_pss_mb(pid: int, each: dict | None = None) -> float:
    """The proportional set size of pid's whole tree in MB: each shared page (the libraries, a
    forked worker's copy of its parent) counted once, shared out between the processes.
    `each`: filled with {process: MB} (a process named by its command's last words)."""
    total = 0
    for p in tree_pids(pid):
        try:
            for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    kb = int(line.split()[1])
                    total += kb
                    if each is not None:
                        name = Path(f"/proc/{p}/cmdline").read_bytes().replace(b"\0", b" ").decode()
                        each[f"{p} {name[:60]}"] = kb / 1024
        except OSError:
            pass
    return total / 1024


def tree_own_mb(pid: int) -> float:
    """The memory pid's whole tree holds in MB: each physical page that any of its processes
    maps counted once, whoever else maps it too (/proc/PID/pagemap's frame numbers; root
    only, else 0.0). Pss shares a library's pages out with every process on the box that
    maps it, so on a box running other Pythons it reads tens of MB low; this is what the
    tree would need on a board of its own."""
    frames = np.concatenate([_frames(p) for p in tree_pids(pid)])
    return len(np.unique(frames[frames != 0])) * 4096 / 2**20


def _frames(pid: int) -> np.ndarray:
    """The page frame numbers of the pages pid has in memory now (none if it ended)."""
    present, pfn = np.uint64(1 << 63), np.uint64((1 << 55) - 1)
    out = [np.zeros(0, np.uint64)]
    try:
        with open(f"/proc/{pid}/maps") as maps, open(f"/proc/{pid}/pagemap", "rb", buffering=0) as pm:
            for line in maps:
                a, b = (int(x, 16) for x in line.split(None, 1)[0].split("-"))
                if a >= 1 << 47:  # the kernel's vsyscall page
                    continue
                pm.seek(a // 4096 * 8)
                e = np.frombuffer(pm.read((b - a) // 4096 * 8), np.uint64)
                out.append(e[(e & present) != 0] & pfn)
    except OSError:
        pass
    return np.concatenate(out)


def tree_rss_mb(pid: int) -> float:
    """The sum of the tree's resident sizes in MB (shared pages in each: cheap to read, it
    tells when to count the tree's own pages)."""
    total = 0
    for p in tree_pids(pid):
        try:
            total += int(Path(f"/proc/{p}/statm").read_text().split()[1])
        except (OSError, IndexError):
            pass
    return total * 4096 / 2**20


def proc_status_mb(pid: int, key: str) -> float | None:
    """A memory figure of /proc/PID/status (VmRSS now, VmHWM the peak) in MB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024  # kB -> MB
    return None
