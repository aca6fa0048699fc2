"""USB sticks: find a mounted mass-storage stick and copy a file onto it, verified.

Detection reads the mount table (/proc/mounts) rather than talking to udisks
over D-Bus: the box's udev rule (systemd/99-inkslice-usb.rules, which starts
inkslice-stick@DEV.service) mounts sticks under /media/inkslice/LABEL, and a
desktop's udisks under the usual places (/media/USER/LABEL, /run/media/USER/LABEL),
and the mount table is the one thing that is there on every image, readable
without privileges and trivially faked in tests. A mount counts as a stick when
  - its mount point is under one of the roots above,
  - it is mounted read-write with a file system a stick uses (vfat, exfat,
    ntfs, ext*, ...),
  - and, when sysfs can tell, its block device is removable or on the USB bus.

The copy (copy_verified):
  1. refuse when the stick has less free space than the file (+1 MiB slack);
  2. write to a temporary name on the stick, fsync the file;
  3. rename to the final name (never overwriting: a suffix -1, -2 is added),
     fsync the folder, so a half-written file never carries the real name;
  4. drop the file's pages from the page cache (posix_fadvise DONTNEED) and
     read it back, compare SHA-256 with the source;
  5. only then report the copy verified. After fsync the data is on the device.

Releasing the stick (release_stick, the long press does it after its copy):
sync, then unmount: `systemctl stop inkslice-stick@DEV.service` for a stick the
box mounted (the polkit rule lets the inkslice user do exactly that), `udisksctl
unmount` for one a desktop mounted. Only when the mount is gone from the mount
table is the stick reported safe to remove: FAT's dirty flag and the stick's
own write cache are then settled too.

Which file goes onto the stick is the daemon's business (BenchService.export_to_usb
for the web, export_latest_gcode for the button's long press): this module copies
a file it is given and knows nothing of jobs.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import threading
from dataclasses import asdict, dataclass
from pathlib import Path

from ..errors import DeviceError

STICK_FS = {
    "vfat",
    "msdos",
    "exfat",
    "ntfs",
    "ntfs3",
    "fuseblk",
    "ext2",
    "ext3",
    "ext4",
    "f2fs",
    "btrfs",
    "xfs",
    "hfsplus",
}
MOUNT_ROOTS = ("/media", "/run/media", "/mnt")
BOX_MOUNTS = "/media/inkslice"  # where inkslice-stick@.service mounts (systemd/inkslice-stick)
SLACK = 1 << 20
FAT_BAD = re.compile(r'[<>:"/\\|?*\x00-\x1f]')


class NoStick(DeviceError):
    """No USB stick is plugged in (or not the one asked for)."""


@dataclass
class Stick:
    id: str  # stable while plugged: the device name (sda1)
    mount: str
    device: str
    fstype: str
    label: str
    free_bytes: int

    def to_json(self):
        return asdict(self)


@dataclass
class CopyResult:
    name: str
    path: str
    bytes: int
    sha256: str
    verified: bool
    safe_to_remove: bool
    unmounted: bool | None = None  # None: not asked to; False: see unmount_problem
    unmount_problem: str = ""

    def to_json(self):
        return asdict(self)


def _unescape(field: str) -> str:
    # /proc/mounts escapes space, tab, newline and backslash as \040 \011 \012 \134
    return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), field)


def _removable(device: str, sys_root: Path) -> bool | None:
    """True/False when sysfs knows, None when it cannot tell (no sysfs entry)."""
    name = os.path.basename(device)
    if not name:
        return None
    block = sys_root / "class" / "block" / name
    if not block.exists():
        return None
    # a partition's removable flag lives on its parent disk
    disk = block if (block / "removable").exists() else block.resolve().parent
    try:
        if (disk / "removable").read_text().strip() == "1":
            return True
    except OSError:
        pass
    return "/usb" in str(block.resolve())


def find_sticks(mounts_file="/proc/mounts", roots=MOUNT_ROOTS, sys_root="/sys") -> list[Stick]:
    try:
        text = Path(mounts_file).read_text()
    except OSError:
        return []
    roots = tuple(str(Path(r)) for r in roots)
    out = []
    for line in text.splitlines():
        parts = line.split()
        if len(parts) < 4:
            continue
        device, mount, fstype, options = (
            _unescape(parts[0]),
            _unescape(parts[1]),
            parts[2],
            parts[3].split(","),
        )
        if fstype not in STICK_FS or "rw" not in options:
            continue
        if not any(mount == r or mount.startswith(r + "/") for r in roots) or mount in roots:
            continue
        if _removable(device, Path(sys_root)) is False:
            continue
        if not os.path.isdir(mount) or not os.access(mount, os.W_OK):
            continue
        try:
            free = shutil.disk_usage(mount).free
        except OSError:
            continue
        out.append(
            Stick(
                id=os.path.basename(device) or mount,
                mount=mount,
                device=device,
                fstype=fstype,
                label=os.path.basename(mount),
                free_bytes=free,
            )
        )
    return out


def safe_name(name: str) -> str:
    """A file name every stick file system accepts (FAT is the strictest)."""
    name = FAT_BAD.sub("_", os.path.basename(name)).strip(" .") or "inkslice.gcode"
    return name[:200]


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def copy_verified(src, folder, name=None) -> CopyResult:
    src, folder = Path(src), Path(folder)
    if not src.is_file():
        raise DeviceError(src, "the file to copy does not exist")
    size = src.stat().st_size
    try:
        free = shutil.disk_usage(folder).free
    except OSError as e:
        raise DeviceError(folder, f"the stick is gone ({e.strerror})") from None
    if free < size + SLACK:
        raise DeviceError(folder, f"not enough space on the stick ({free} bytes free, {size} needed)")
    name = safe_name(name or src.name)
    stem, dot, ext = name.rpartition(".")
    if not dot:
        stem, ext = name, ""
    final = folder / name
    i = 1
    while final.exists():  # never overwrite what is on the operator's stick
        final = folder / (f"{stem}-{i}.{ext}" if dot else f"{stem}-{i}")
        i += 1
    tmp = folder / f".{final.name}.inkslice-tmp"
    want = hashlib.sha256()
    try:
        with open(src, "rb") as fin, open(tmp, "wb") as fout:
            for chunk in iter(lambda: fin.read(1 << 20), b""):
                want.update(chunk)
                fout.write(chunk)
            fout.flush()
            os.fsync(fout.fileno())
        os.rename(tmp, final)
        dfd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError as e:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise DeviceError(folder, f"copy failed: {e.strerror or e}") from None
    # Read back from the device, not from the page cache we just filled.
    try:
        fd = os.open(final, os.O_RDONLY)
        try:
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
        finally:
            os.close(fd)
    except (OSError, AttributeError):
        pass
    got = _sha256(final)
    ok = got == want.hexdigest()
    if not ok:
        raise DeviceError(final, "verification failed: the copy on the stick differs from the job's file")
    return CopyResult(
        name=final.name, path=str(final), bytes=size, sha256=got, verified=True, safe_to_remove=True
    )


def _unmount_command(stick: Stick) -> list[str] | None:
    dev = os.path.basename(stick.device)
    if stick.mount.startswith(BOX_MOUNTS + "/") and re.fullmatch(r"[A-Za-z0-9]+", dev):
        return ["systemctl", "stop", f"inkslice-stick@{dev}.service"]
    if shutil.which("udisksctl") and stick.device.startswith("/dev/"):
        return ["udisksctl", "unmount", "--no-user-interaction", "-b", stick.device]
    return None


def unmount_stick(stick: Stick) -> None:
    """Ask whoever mounted the stick to unmount it; raise DeviceError when that fails."""
    cmd = _unmount_command(stick)
    if cmd is None:
        raise DeviceError(stick.mount, "no way to unmount it here (not mounted by the box, no udisksctl)")
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise DeviceError(stick.mount, f"{cmd[0]} failed ({e})") from None
    if r.returncode != 0:
        last = (r.stderr or r.stdout).strip().splitlines()[-1:] or [f"exit code {r.returncode}"]
        raise DeviceError(stick.mount, f"{cmd[0]}: {last[0]}")


class UsbExporter:
    """The small interface the web and the button use: sticks() and export().

    unmount(stick) is how a stick is released after a copy (unmount_stick on the box;
    tests pass their own)."""

    def __init__(
        self,
        mounts_file="/proc/mounts",
        roots=MOUNT_ROOTS,
        sys_root="/sys",
        subfolder="inkslice",
        unmount=unmount_stick,
    ):
        self.mounts_file, self.roots, self.sys_root, self.subfolder = mounts_file, roots, sys_root, subfolder
        self.unmount = unmount
        self._lock = threading.Lock()  # one copy at a time: sticks are slow and FAT is fragile

    def sticks(self) -> list[Stick]:
        return find_sticks(self.mounts_file, self.roots, self.sys_root)

    def export(self, src, stick_id=None, name=None, release=False) -> CopyResult:
        """Copy src onto the stick, verified; with release, sync and unmount it afterwards."""
        sticks = self.sticks()
        stick = (
            next((s for s in sticks if s.id == stick_id), None)
            if stick_id
            else (sticks[0] if sticks else None)
        )
        if stick is None:
            raise NoStick("usb", "no USB stick is plugged in" if not sticks else f"no stick {stick_id!r}")
        folder = Path(stick.mount) / self.subfolder if self.subfolder else Path(stick.mount)
        with self._lock:
            try:
                folder.mkdir(exist_ok=True)
            except OSError as e:
                raise DeviceError(stick.mount, f"cannot write to the stick ({e.strerror})") from None
            result = copy_verified(src, folder, name)
            if release:
                self._release(stick, result)
            return result

    def _release(self, stick: Stick, result: CopyResult) -> None:
        os.sync()
        try:
            self.unmount(stick)
            gone = all(s.mount != stick.mount for s in self.sticks())
            problem = "" if gone else "it is still mounted"
        except DeviceError as e:
            gone, problem = False, e.problem
        result.unmounted, result.unmount_problem, result.safe_to_remove = gone, problem, gone
