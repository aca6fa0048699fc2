"""The job manager: what the operator does with jobs the box has kept.

Rename, delete, process a kept scan again with other settings, post a finished height map again
for another machine (repost.py), and the bytes each job takes on the data disk. None of these
captures anything; they are refused for a job while its scan or processing runs.

JobManager(service) uses of the service: store, scan_running(), lock, current, publish(),
refuse_if_busy() and job_thread (jobthread.py: the thread that processes a kept scan).
"""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

from ..errors import DeviceError, SettingError
from . import repost as R
from . import settings as S
from .store import ACTIVE

log = logging.getLogger("inkslice.jobs")
NAME_MAX = 80


def folder_bytes(folder: Path) -> int:
    total = 0
    for p in Path(folder).rglob("*"):
        try:
            if p.is_file() and not p.is_symlink():
                total += p.stat().st_size
        except OSError:
            pass
    return total


def refuse_while_active(job: dict, then: str = "stop it first") -> None:
    if job["status"] in ACTIVE:
        raise DeviceError("job", f"job {job['id']} is {job['status']}; {then}")


class JobManager:
    def __init__(self, service):
        self.service = service
        self.store = service.store
        self._sizes: dict[str, tuple] = {}  # job id -> ((status, finished), bytes on disk)

    def rename(self, job_id: str, name: str) -> dict:
        name = " ".join(str(name or "").split())[:NAME_MAX]
        if not name:
            raise SettingError("name", f"a job needs a name (1 to {NAME_MAX} characters)")
        self.store.get_job(job_id)
        self.store.update_job(job_id, name=name)
        self.store.event(job_id, "renamed", f"renamed {name!r}")
        return self.store.get_job(job_id)

    def delete(self, job_id: str) -> None:
        svc = self.service
        with svc.lock:
            job = self.store.get_job(job_id)
            current = svc.current["job_id"] == job_id
            if current:
                svc.job_thread.join_if_over(job_id)  # the job is over; its thread is closing up
            if current and (svc.scan_running() or job["status"] in ACTIVE):
                raise DeviceError("job", f"job {job_id} is {job['status']}; stop it first")
            self.store.delete_job(job_id)
            shutil.rmtree(self.store.job_dir(job_id), ignore_errors=True)
            self._sizes.pop(job_id, None)
            if current:
                svc.publish(
                    job_id=None, state="idle", message="ready", levels_done=0, levels_total=0, eta_s=None
                )
        log.info("job %s deleted", job_id)

    def reprocess(self, job_id: str, changes: dict | None) -> str:
        changes = dict(changes or {})
        for key in changes:
            if key not in S.DEFAULTS:
                raise SettingError(key, "unknown setting")
        svc = self.service
        with svc.lock:
            svc.refuse_if_busy()
            job = self.store.get_job(job_id)
            refuse_while_active(job)
            if not (self.store.job_dir(job_id) / "scan" / "scan.json").is_file():
                raise SettingError("job", f"job {job_id} kept no scan to process")
            settings = S.validate(S.full(job["settings"]), changes)
            self.store.update_job(
                job_id, status="processing", settings=settings, reason="", finished=None, interrupted=0
            )
            self.store.event(job_id, "reprocess", "processed again" + (f" with {changes}" if changes else ""))
            self._sizes.pop(job_id, None)
            svc.job_thread.start_processing(job_id)
            return job_id

    def repost(self, job_id: str, options: dict | None) -> list[str]:
        with self.service.lock:
            job = self.store.get_job(job_id)
            refuse_while_active(job, "wait for it to finish")
        names = R.repost(self.store.job_dir(job_id), job_id, S.full(job["settings"]), options or {})
        with self.service.lock:
            job = self.store.get_job(job_id)
            self.store.update_job(job_id, outputs=sorted(set(job.get("outputs") or []) | set(names)))
            self.store.event(
                job_id, "reposted", "posted again: " + ", ".join(n for n in names if n.endswith(".nc"))
            )
            self._sizes.pop(job_id, None)
        return names

    def sizes(self) -> dict[str, int]:
        """Bytes on disk per job (its folder), counted once per finished job."""
        out = {}
        for job in self.store.list_jobs():
            key = (job["status"], job["finished"])
            hit = self._sizes.get(job["id"])
            if hit is None or hit[0] != key or job["status"] in ACTIVE:
                hit = (key, folder_bytes(self.store.job_dir(job["id"])))
                self._sizes[job["id"]] = hit
            out[job["id"]] = hit[1]
        return out
