"""A full data disk is a fault like any other, never a stuck job.

The data folder lives on a small tmpfs of its own (mounted here, as root;
without root the tests are skipped, saying so): the disk really fills, and
SQLite and the frame writer meet the real ENOSPC, no injection. Filled
mid-scan and mid-processing, the job ends `failed` with a reason that starts
"disk:", no new scan is taken while its end is not stored, and once space is
freed it resumes to the same result as an uninterrupted scan.
"""

import errno
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from daemon_helpers import SCAN, read_heightmap, service, wait_final

from appliance.daemon.processing import child_process
from appliance.daemon.recovery import audit
from appliance.daemon.store import ACTIVE, DiskFull, Store
from appliance.errors import DeviceError

DISK_MB = 16  # a scan of the cone with its outputs takes ~1.5 MB


def roomy(path):
    """What the min_free_mb guard is told: plenty. The guard stops a scan before the disk is full
    when it is the scan that fills it; these tests are about what it cannot see coming (something
    else filling the disk between two frames), so the writes themselves meet ENOSPC."""
    return 1e6


class SmallDisk:
    """A tmpfs of DISK_MB that fill() makes completely full and free() empties again."""

    def __init__(self, mount):
        self.mount = mount
        self.filler = mount / "filler"

    def fill(self):
        fd = os.open(self.filler, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
        try:
            for chunk in (1 << 20, 4096, 1):
                try:
                    while True:
                        os.write(fd, b"\0" * chunk)
                except OSError as e:
                    assert e.errno == errno.ENOSPC, e
        finally:
            os.close(fd)
        assert os.statvfs(self.mount).f_bavail == 0

    def free(self):
        self.filler.unlink()


@pytest.fixture
def small_disk(tmp_path):
    mount = tmp_path / "disk"
    mount.mkdir()
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={DISK_MB}m", "tmpfs", str(mount)],
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs to fill (needs root): {r.stderr.strip()}")
    try:
        yield SmallDisk(mount)
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=True)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The same scan, uninterrupted, on an ordinary disk."""
    svc, _ = service(tmp_path_factory.mktemp("ref"))
    try:
        job = wait_final(svc, svc.start_scan(SCAN), 300)
        assert job["status"] == "done", job["reason"]
        return result_of(svc, job["id"])
    finally:
        svc.close()


def result_of(svc, job_id):
    scan = json.loads(svc.job_file(job_id, "scan/scan.json").read_text())
    return [f["level_mm"] for f in scan["frames"]], read_heightmap(svc.job_file(job_id, "heightmap.csv"))


def assert_same_result(got, want):
    (levels, heights), (ref_levels, ref_heights) = got, want
    assert levels == ref_levels
    assert heights.shape == ref_heights.shape
    assert np.array_equal(np.isnan(heights), np.isnan(ref_heights))
    assert np.nanmax(np.abs(heights - ref_heights)) <= 0.005


def test_the_store_turns_sqlite_disk_full_into_a_disk_fault_and_keeps_a_jobs_end_until_it_fits(small_disk):
    store = Store(small_disk.mount)
    store.create_job("j1", "cone", {}, {}, 10)
    store.update_job("j1", status="scanning")
    small_disk.fill()
    with pytest.raises(DiskFull) as caught:
        store.update_job("j1", levels_done=3)
    assert str(caught.value).startswith("disk: full: the job store cannot write (database or disk is full)")
    assert not store._db.in_transaction  # SQLite's own rollback was not fought
    with pytest.raises(DiskFull):
        store.update_job("j1", status="failed", reason="disk: full while writing")
    store.event("j1", "failed", "disk: full while writing")  # held, not raised
    job = store.get_job("j1")
    assert (job["status"], job["reason"]) == ("failed", "disk: full while writing")
    assert store.list_jobs(ACTIVE) == []
    assert store.unwritten() == {"j1": {"status": "failed", "reason": "disk: full while writing"}}
    with pytest.raises(DiskFull):
        store.flush_unwritten()
    small_disk.free()
    store.flush_unwritten()
    assert store.unwritten() == {}
    store.close()
    again = Store(small_disk.mount)  # really on disk, not only in memory
    try:
        assert again.get_job("j1")["status"] == "failed"
        assert [e["kind"] for e in again.events("j1")][:1] == ["failed"]
        assert again.integrity_ok()
    finally:
        again.close()


def fill_after_frames(svc, disk, n):
    """The disk fills up right after frame n is on disk, before the job row catches up with it."""
    keep = svc.keep_frame

    def on_frame(image, info):
        keep(image, info)
        if (
            len(list((disk.mount / "data" / "jobs").glob("*/scan/frames/*.png"))) == n
            and not disk.filler.exists()
        ):
            disk.fill()

    svc.keep_frame = on_frame


def filling_processor(disk, processor):
    """Processing meets a full disk the first time; runs normally afterwards."""

    def process(*args):
        if not disk.filler.exists() and not getattr(process, "filled", False):
            disk.fill()
            process.filled = True
        return processor(*args)

    return process


def end_on_a_full_disk_then_resume(svc, disk, reference):
    job_id = svc.start_scan(SCAN)
    job = wait_final(svc, job_id, 300)
    assert job["status"] == "failed" and job["reason"].startswith("disk: full"), job
    print(f"\nfailed at {job['levels_done']} levels: {job['reason']}")
    assert svc.state()["state"] == "failed"
    assert svc.state()["hardware"]["disk"].startswith("fault: full")
    with pytest.raises(DeviceError) as refused:  # nothing new while the disk is full
        svc.start_scan(SCAN)
    assert str(refused.value).startswith("disk: full")
    assert [j["id"] for j in svc.jobs()] == [job_id]
    disk.free()
    svc.resume(job_id)
    job = wait_final(svc, job_id, 300)
    assert job["status"] == "done", job["reason"]
    assert job["attempts"] == 2
    assert_same_result(result_of(svc, job_id), reference)
    assert audit(svc.store) == []
    return job


def test_a_disk_that_fills_mid_scan_fails_the_job_which_resumes_once_space_is_freed(small_disk, reference):
    svc, _ = service(small_disk.mount, disk_free_mb=roomy)
    try:
        fill_after_frames(svc, small_disk, 4)
        job = end_on_a_full_disk_then_resume(svc, small_disk, reference)
        assert job["levels_done"] == job["levels_total"] > 10  # the plan's 10 and the refinement's
    finally:
        svc.close()


def test_a_disk_that_fills_during_processing_fails_the_job_which_resumes_once_space_is_freed(
    small_disk, reference
):
    """Processing in its child process, as in the daemon: the child reports the full disk in one line."""
    svc, _ = service(
        small_disk.mount, processor=filling_processor(small_disk, child_process), disk_free_mb=roomy
    )
    try:
        end_on_a_full_disk_then_resume(svc, small_disk, reference)
    finally:
        svc.close()


def killed_mid_scan(data):
    """A daemon's store with job j1 scanning, left as a SIGKILL leaves it (write-ahead log and all)."""
    code = (
        "import os, sys; from appliance.daemon.store import Store; s = Store(sys.argv[1]); "
        "s.create_job('j1', 'cone', {}, {}, 10); s.update_job('j1', status='scanning'); os._exit(0)"
    )
    subprocess.run([sys.executable, "-c", code, str(data)], check=True)


def test_a_restart_on_a_full_disk_marks_the_interrupted_job_in_memory_and_stores_it_later(small_disk):
    data = small_disk.mount / "data"
    killed_mid_scan(data)
    small_disk.fill()
    svc, _ = service(small_disk.mount)
    try:
        job = svc.job("j1")
        assert job["status"] == "failed" and job["interrupted"] and job["reason"].startswith("interrupted")
        with pytest.raises(DeviceError) as refused:
            svc.resume("j1")
        assert str(refused.value).startswith("disk: full: the end of job j1 (failed) is not yet stored")
        small_disk.free()
        svc.resume("j1")  # writes the mark first, then resumes
        assert svc.job("j1")["attempts"] == 2
    finally:
        svc.close()


def test_a_store_that_cannot_even_open_says_the_disk_is_full(small_disk):
    data = small_disk.mount / "data"
    Store(data).close()  # a clean stop: no write-ahead log left
    small_disk.fill()
    with pytest.raises(DiskFull, match="^disk: full: the job store cannot write"):
        Store(data)


def test_a_jobs_end_held_back_by_a_full_disk_is_written_when_the_daemon_stops_after_space_returns(small_disk):
    data = small_disk.mount / "data"
    store = Store(data)
    store.create_job("j1", "cone", {}, {}, 10)
    store.update_job("j1", status="scanning")
    small_disk.fill()
    with pytest.raises(DiskFull):
        store.update_job("j1", status="failed", reason="disk: full while writing")
    small_disk.free()
    store.close()  # nobody started a scan in between
    again = Store(data)
    try:
        assert (again.get_job("j1")["status"], again.get_job("j1")["reason"]) == (
            "failed",
            "disk: full while writing",
        )
    finally:
        again.close()
