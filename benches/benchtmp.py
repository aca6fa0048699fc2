"""A bench's scratch folder: removed when the bench ends, or kept to look into (--keep).

Benches that run the daemon as a subprocess (daemon.py, keepup.py) need a real folder
for its data, socket and log that outlives a crash of the daemon, and a way to keep it
when a figure looks wrong.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


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
