"""Files written so that a reader never sees half of one.

The SD card of the bench box can lose power at any moment. Every file we
write goes to a temporary name in the same folder, is fsynced, and is then
renamed over the final name (rename is atomic on POSIX file systems); the
folder is fsynced too so the rename itself survives a power cut.
"""

import json
import os
import shutil
import tempfile
from pathlib import Path


def fsync_dir(folder):
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_bytes(path, data: bytes):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    fsync_dir(path.parent)


def write_text(path, text: str):
    write_bytes(path, text.encode("utf-8"))


def write_json(path, obj):
    write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")


# -- a whole folder at once ----------------------------------------------------------
#
# A job's outputs are a set: a G-code program from one run beside a height map from
# another is a wrong part waiting to be milled. So an output folder is never edited
# file by file: the new set is built in a hidden sibling folder (same file system,
# so renaming is atomic) and swapped in with one rename. A crash at any moment
# leaves OUT holding either the whole old set or the whole new one.

STAGING_PREFIX = ".inkslice-"


def check_output_folder(out, ours=None, keep=()):
    """Refuse an output folder we could not replace, before any long work:
    -> InkSliceError naming the problem (OUT is a file, its parent is missing or read-only).

    `ours(name)` says whether a file name is one a run writes: the folder is replaced whole,
    so one holding anything else (`-o .`, the scan itself) is refused, not emptied."""
    from .errors import InkSliceError

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InkSliceError(out, "exists and is not a folder; give a folder for the outputs")
    if ours is not None and out.is_dir():
        foreign = sorted(
            p.name for p in out.iterdir() if p.name not in keep and not (p.is_file() and ours(p.name))
        )
        if foreign:
            raise InkSliceError(
                out,
                f"holds {foreign[0]!r}, which no run wrote; the output folder is "
                "replaced whole, so give a new or empty folder (or an earlier output folder)",
            )
    parent = out.absolute().parent
    probe = parent
    while not probe.exists():  # OUT and missing parents are created
        probe = probe.parent
    if not probe.is_dir():
        raise InkSliceError(out, f"cannot be created: {probe} is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InkSliceError(out, f"cannot be written: no permission to write in {probe}")
    if out.is_dir() and not os.access(out, os.R_OK | os.X_OK):
        raise InkSliceError(out, "cannot be read, so it cannot be replaced")


def check_output_file(path, option="-o"):
    """Refuse a file we could not write at `path` (created or replaced), before the work:
    -> InkSliceError naming the problem (a folder, a missing or read-only parent)."""
    from .errors import InkSliceError

    path = Path(path)
    if path.is_dir():
        raise InkSliceError(path, f"is a folder; give {option} a file name")
    parent = path.absolute().parent
    if not parent.is_dir():
        raise InkSliceError(path, f"cannot be written: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InkSliceError(path, f"cannot be written: no permission to write in {parent} (or read-only)")


def replace_folder(out, files: dict, keep=()):
    """Make folder `out` hold exactly `files` ({name: bytes}) plus the entries named in
    `keep` that it holds now (the daemon keeps the scan inside its job folder), all at once.

    Kept entries are hard-linked into the new folder (no data copied; copied where the
    file system cannot link), so the swap never moves or risks them."""
    out = Path(out).absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    clear_staging(out)
    new = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{out.name}.new.", dir=out.parent))
    try:
        for name, data in files.items():
            _write_new(new / name, data)
        for name in keep:
            src = out / name
            if src.is_dir():
                shutil.copytree(src, new / name, copy_function=_link_or_copy, symlinks=True)
            elif src.exists():
                _link_or_copy(src, new / name)
        fsync_dir(new)
        if out.exists():
            os.chmod(new, os.stat(out).st_mode & 0o7777)
            _swap(new, out)  # `new` now names the old set
        else:
            os.rename(new, out)
        fsync_dir(out.parent)
    finally:
        shutil.rmtree(new, ignore_errors=True)


def clear_staging(out):
    """Tidy what a crashed run left beside `out`: an old set parked mid-swap goes back
    (`out` is missing only then), half-built new sets are removed."""
    out = Path(out).absolute()
    if not out.parent.is_dir():
        return
    parked = sorted(out.parent.glob(f"{STAGING_PREFIX}{out.name}.old.*"))
    if parked and not out.exists():
        os.rename(parked[0], out)
    for old in out.parent.glob(f"{STAGING_PREFIX}{out.name}.*"):
        shutil.rmtree(old, ignore_errors=True)


def _write_new(path, data: bytes):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "xb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _link_or_copy(src, dst):
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)
    return dst


_RENAME_EXCHANGE = 2


def _swap(a: Path, b: Path):
    """Exchange two folders' names atomically (Linux renameat2); where the kernel or
    file system cannot, two renames with the old set parked beside under a staging
    name (a crash between them leaves the old set there and `b` missing, never mixed)."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        fn = None
    if fn is not None:
        AT_FDCWD = -100
        if fn(AT_FDCWD, os.fsencode(str(a)), AT_FDCWD, os.fsencode(str(b)), _RENAME_EXCHANGE) == 0:
            return
    parked = b.parent / f"{STAGING_PREFIX}{b.name}.old.{os.getpid()}"
    os.rename(b, parked)
    os.rename(a, b)
    os.rename(parked, a)
