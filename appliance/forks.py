"""Work forked onto the other cores, where that is safe: the fit's sweeps over the frames
and the nodes (surface/), the finishing planner and its tails (cam/).

A fork copies only the thread that calls it: in a process with another thread alive (the
daemon's web server and job runner) a lock that thread held stays held in the copy forever.
So forking is allowed only by a process that knows it has no other thread (the processing
child's main, `allow_workers`; a command, `workers_allowed`), and even then only while no
other Python thread is alive (the command line's progress ticker excepted: a worker never
draws). Everywhere else the work runs here, in one piece.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import signal
import threading
from contextlib import contextmanager

import numpy as np

from .errors import InkSliceError
from .progress import TICKER

ITEM_POINTS = 20  # an item's fixed cost (its calls, its tree), in the points its weight counts
MAX_WORKERS = 2  # each worker holds its own envelopes (~30 MB on the demo's part): 1 GB boxes

_allowed = 1


def allow_workers(n: int | None = None) -> int:
    """Let the fit and the finishing work in up to `n` processes at once (default: the cores
    this process may use, at most MAX_WORKERS), for the rest of this process: the
    processing child's main.
    Two is what the planner uses (bands.py: one planner from each end)."""
    global _allowed
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    _allowed = max(1, min(MAX_WORKERS, cores) if n is None else int(n))
    return _allowed


@contextmanager
def workers_allowed(n: int | None = None):
    """allow_workers for the block only (a command run in-process by a caller leaves the
    caller as it was)."""
    before = _allowed
    allow_workers(n)
    try:
        yield
    finally:
        allow_workers(before)


def workers() -> int:
    """Bands to plan at once now: a fork copies only the calling thread, so with another
    Python thread alive (a web server, a job runner) the planner stays in one."""
    alone = all(t is threading.main_thread() or t.name == TICKER for t in threading.enumerate())
    return _allowed if alone else 1


def in_parts(work, weights, join):
    """work(a, b) over items [a, b) of a list, the items split into contiguous parts of about
    equal weight, one part a worker (as many as workers() allows) -> join([each part's result])."""
    cum = np.cumsum(np.asarray(weights, float))
    parts = workers() if cum.size > 1 and cum[-1] > 0 else 1
    cuts = np.searchsorted(cum, cum[-1] * np.arange(1, parts) / parts) + 1 if parts > 1 else []
    bounds = [0, *sorted({int(c) for c in cuts if 0 < c < len(cum)}), len(cum)]
    tasks = [(lambda a=a, b=b: work(a, b)) for a, b in zip(bounds[:-1], bounds[1:])]
    return join(in_workers(tasks) if len(tasks) > 1 else [tasks[0]()])


def joined(parts: list) -> list:
    """in_parts' join for work that returns a list per part: the parts' items in order."""
    return [item for part in parts for item in part]


def each_in_parts(item, weights) -> list:
    """[item(i) for each i of range(len(weights))], the items in parts of about equal weight
    (in_parts): for items that need nothing of each other's results."""
    return in_parts(lambda a, b: [item(i) for i in range(a, b)], weights, joined)


def in_workers(tasks: list) -> list:
    """Each task's result, the first run here and the others in forked children."""
    children, parent = [], os.getpid()
    for task in tasks[1:]:
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the worker: run, send, leave without running the parent's exit code
            os.close(r)
            _die_with(parent)
            code = 0
            try:
                data = pickle.dumps(("ok", task()))
            except BaseException as e:  # sent to the parent, raised there
                data, code = pickle.dumps(("error", f"{type(e).__name__}: {e}")), 1
            with os.fdopen(w, "wb") as out:
                out.write(data)
            os._exit(code)
        os.close(w)
        children.append((pid, r))
    try:
        results = [tasks[0]()]
    finally:
        received = [_receive(pid, r) for pid, r in children]
    for kind, value in received:
        if kind != "ok":
            raise InkSliceError("worker", f"a forked worker failed: {value}")
        results.append(value)
    return results


def _die_with(parent: int):
    """A worker is killed with its parent (a cancelled job's child is SIGKILLed: its workers
    must not run on, writing into a pipe nobody reads)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass
    if os.getppid() != parent:  # it died before the line above
        os._exit(1)


def _receive(pid: int, fd: int):
    with os.fdopen(fd, "rb") as inp:
        data = inp.read()  # read before waiting: a full pipe would block the worker
    _, status = os.waitpid(pid, 0)
    if not data:
        code = os.waitstatus_to_exitcode(status)
        return "error", f"it ended with {'signal ' + str(-code) if code < 0 else 'exit code ' + str(code)}"
    return pickle.loads(data)
