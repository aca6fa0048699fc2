"""After a crash, a kill -9 or a power cut: find the jobs that were running,
make their scan folders exactly what scan.json says, and mark them so the
operator (or auto_resume) can continue them.

Nothing captured is thrown away: scan.json only ever lists fully written
frames (see runner.py), so the frames it lists are kept; what is removed is
temporary files (half-written by definition) and PNGs that were complete but
not yet listed (the resume captures that level again, identically).

Also removed at start: the staging folders of imports the daemon was killed
in the middle of (JOBS/.import-*, see importing.py). audit() counts every
stray temporary the appliance writes on the data disk: those, the web's
upload folders (DATA/web/uploads/.incoming-*, the web removes them at its
start) and half-written files.
"""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

from ..errors import InkSliceError
from ..scanfile import load_scan, read_frame
from .store import ACTIVE, DiskFull, Store

log = logging.getLogger("inkslice.recovery")


def _remove_temporaries(folder: Path) -> int:
    n = 0
    for tmp in folder.rglob(".*.tmp"):
        tmp.unlink(missing_ok=True)
        n += 1
    return n


def repair_scan_folder(scan_dir: Path) -> list:
    """Make the folder agree with its scan.json; return its frames (empty when none was saved)."""
    if not scan_dir.is_dir():
        return []
    _remove_temporaries(scan_dir.parent)
    if not (scan_dir / "scan.json").is_file():
        frames = []
    else:
        frames = load_scan(scan_dir).frames
    listed = {f.file for f in frames}
    for png in sorted((scan_dir / "frames").glob("*.png")):
        rel = f"frames/{png.name}"
        if rel not in listed:
            log.info("removing %s: written but not yet listed in scan.json when the daemon stopped", png)
            png.unlink()
    return frames


def stray_imports(store: Store) -> list[Path]:
    """Staging folders of imports (importing.py) that a kill left behind."""
    return sorted(store.jobs_dir.glob(".import-*"))


def remove_stray_imports(store: Store) -> int:
    """Remove JOBS/.import-*: an import is renamed into place only when complete, so any left is junk."""
    n = 0
    for folder in store.jobs_dir.glob(".import-*"):
        log.info("removing %s: an import the daemon was stopped in the middle of", folder)
        shutil.rmtree(folder, ignore_errors=True)
        n += 1
    return n


def recover(store: Store) -> list[str]:
    """Mark every job left in an active state as interrupted (status failed); return their ids.

    On a full disk the mark is held in memory (store.py) and written once there is room."""
    remove_stray_imports(store)
    found = []
    for job in store.list_jobs(ACTIVE):
        scan_dir = store.job_dir(job["id"]) / "scan"
        try:
            frames = repair_scan_folder(scan_dir)
        except InkSliceError as e:  # cannot happen with atomic writes; say so if it does
            store.update_job(
                job["id"],
                status="failed",
                interrupted=1,
                reason=f"interrupted, and the scan folder is unreadable: {e}",
            )
            found.append(job["id"])
            continue
        n = len(frames)
        reason = (
            f"interrupted: the daemon stopped while {job['status']} (power loss, crash or kill) "
            f"with {n} level{'s' if n != 1 else ''} captured; resume to continue"
        )
        try:
            store.update_job(
                job["id"],
                status="failed",
                interrupted=1,
                reason=reason,
                levels_done=n,
                level_mm=frames[-1].level_mm if frames else None,
            )
        except DiskFull as e:
            log.warning("job %s: %s", job["id"], e)
        store.event(job["id"], "interrupted", reason)
        log.warning("job %s: %s", job["id"], reason)
        found.append(job["id"])
    return found


def audit(store: Store) -> list[str]:
    """Every inconsistency between the store and the files (empty list = consistent)."""
    problems = []
    if not store.integrity_ok():
        problems.append("database: integrity check failed")
    stray = stray_imports(store)
    if stray:
        mib = sum(f.stat().st_size for d in stray for f in d.rglob("*") if f.is_file()) / 2**20
        problems.append(
            f"jobs: imports left half-copied (removed when the daemon starts), {mib:.1f} MiB: "
            f"{[d.name for d in stray]}"
        )
    for job in store.list_jobs():
        jid, scan_dir = job["id"], store.job_dir(job["id"]) / "scan"
        temporaries = list(store.job_dir(jid).rglob(".*.tmp"))
        if temporaries:
            problems.append(f"{jid}: temporary files left: {[t.name for t in temporaries]}")
        frames = []
        if (scan_dir / "scan.json").is_file():
            try:
                scan = load_scan(scan_dir)
                frames = scan.frames
                for ref in frames:
                    read_frame(scan, ref)
            except InkSliceError as e:
                problems.append(f"{jid}: {e}")
                continue
        if job["status"] not in ACTIVE and job["levels_done"] != len(frames):
            problems.append(
                f"{jid}: the store says {job['levels_done']} levels, scan.json lists {len(frames)}"
            )
        for name in job["outputs"]:
            if not (store.job_dir(jid) / name).is_file():
                problems.append(f"{jid}: output {name} is listed but missing")
    # the web shares this data folder; what it was unpacking when killed stays until it restarts
    stray = sorted(p.name for p in (store.data_dir / "web" / "uploads").glob(".incoming-*"))
    if stray:
        problems.append(f"web: uploads left half-unpacked (removed when the web starts): {stray}")
    return problems
