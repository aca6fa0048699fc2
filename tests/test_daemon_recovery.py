"""The daemon as a real process: SIGKILL at random points of a scan, ten
times; each restart finds a consistent store and intact files, and the
resumed scan equals an uninterrupted one. Device faults injected into the
daemon process end the job with a clear reason."""

import json
import os
import random
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from daemon_helpers import FINAL, SCAN, read_heightmap, service, wait_final
from polling import wait_until

from appliance.daemon.recovery import audit
from appliance.daemon.rpc import BenchClient
from appliance.daemon.store import Store
from appliance.errors import DeviceError

# moves and settling take real time (a level ~0.3 s, homing ~0.5 s), so kills land in every phase
SLOW_STAGE = {"stage": {"seconds_per_mm": 0.01}}
PARAMS = {**SCAN, "settle_s": 0.15}


class Daemon:
    def __init__(self, tmp_path, faults=None):
        self.data, self.sock = tmp_path / "data", tmp_path / "d.sock"
        self.log = open(tmp_path / "daemon.log", "ab")
        cmd = [
            sys.executable,
            "-m",
            "appliance.cli",
            "daemon",
            "--sim",
            "fake",
            "--surface",
            "cone",
            "--data",
            str(self.data),
            "--socket",
            str(self.sock),
            "--faults",
            json.dumps(faults or {}),
        ]
        self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=self.log)
        self.client = BenchClient(self.sock, timeout=10)

        def up():
            if self.proc.poll() is not None:
                raise AssertionError(f"the daemon exited: {(tmp_path / 'daemon.log').read_text()}")
            return self.client.state()

        wait_until(up, 30, what="the daemon to answer", every=0.05, ignoring=DeviceError)

    def kill(self):
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()
        self.log.close()

    def stop(self):
        self.proc.terminate()
        assert self.proc.wait(timeout=30) == 0  # SIGTERM is a clean stop
        self.log.close()


def wait_job(client, job_id, timeout=60):
    """The job once it has finished and the bench says so too."""

    def finished():
        job = client.job(job_id)
        return job if job["status"] in FINAL and client.state()["state"] == job["status"] else None

    return wait_until(
        finished, timeout, what=lambda: f"job {job_id} to finish: {client.job(job_id)}", every=0.05
    )


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The same scan, uninterrupted, in-process."""
    svc, _ = service(tmp_path_factory.mktemp("ref"))
    try:
        job = wait_final(svc, svc.start_scan(PARAMS))
        assert job["status"] == "done"
        scan = json.loads(svc.job_file(job["id"], "scan/scan.json").read_text())
        return read_heightmap(svc.job_file(job["id"], "heightmap.csv")), [
            f["level_mm"] for f in scan["frames"]
        ]
    finally:
        svc.close()


def audit_of(data):
    """What `inkslice audit` finds in a stopped daemon's data folder."""
    store = Store(data)
    try:
        return audit(store)
    finally:
        store.close()


def check_result(client, job_id, ref_map, ref_levels):
    job = wait_job(client, job_id)
    assert job["status"] == "done", job["reason"]
    scan = json.loads(client.job_file(job_id, "scan/scan.json").read_text())
    assert [f["level_mm"] for f in scan["frames"]] == ref_levels
    got = read_heightmap(client.job_file(job_id, "heightmap.csv"))
    assert got.shape == ref_map.shape
    assert np.nanmax(np.abs(got - ref_map)) <= 0.005
    assert np.array_equal(np.isnan(got), np.isnan(ref_map))


@pytest.mark.slow
def test_sigkill_ten_times_then_resume_equals_an_uninterrupted_scan(tmp_path, reference):
    """Ten kills that land mid-job (a kill after the end does not count; the
    finished job is checked and a new one started)."""
    ref_map, ref_levels = reference
    rng = random.Random(20131)
    daemon = Daemon(tmp_path, SLOW_STAGE)
    job_id = daemon.client.start_scan(PARAMS)
    phases, landed, finished = [], 0, 0
    for attempt in range(30):
        if landed == 10:
            break
        # a random point of what is left: ~0.4 s a level still to capture, then processing
        left = 10 - daemon.client.job(job_id)["levels_done"]
        time.sleep(rng.uniform(0.1, 0.8 + 0.4 * left))
        st = daemon.client.state()
        daemon.kill()
        store = Store(daemon.data)
        try:
            mid_job = store.get_job(job_id)["status"] in ("homing", "scanning", "processing")
        finally:
            store.close()
        daemon = Daemon(tmp_path, SLOW_STAGE)
        store = Store(daemon.data)
        try:
            # whatever it was doing, the store and the files are consistent after recovery
            assert audit(store) == [], f"after kill {attempt + 1} ({st['state']}@{st['levels_done']})"
        finally:
            store.close()
        job = daemon.client.job(job_id)
        if not mid_job:
            check_result(daemon.client, job_id, ref_map, ref_levels)
            finished += 1
            job_id = daemon.client.start_scan(PARAMS)
            continue
        landed += 1
        phases.append(f"{st['state']}@{st['levels_done']}")
        assert job["status"] == "failed" and job["interrupted"] and job["reason"].startswith("interrupted"), (
            job
        )
        daemon.client.resume(job_id)
    print(f"killed mid-job at: {', '.join(phases)}; jobs finished between kills: {finished}")
    assert landed == 10, phases
    check_result(daemon.client, job_id, ref_map, ref_levels)
    daemon.stop()


@pytest.mark.slow
@pytest.mark.parametrize(
    "faults, text",
    [
        ({"camera": {"unplug_after": 3}}, "camera"),
        ({"stage": {"reset_after_moves": 4}}, "stage: the controller was reset"),
        ({"disk": {"after_frames": 2, "free_mb": 150}}, "disk: nearly full"),
    ],
)
def test_faults_in_the_daemon_process_end_with_a_clear_reason(tmp_path, faults, text):
    daemon = Daemon(tmp_path, faults)
    try:
        job_id = daemon.client.start_scan(PARAMS)
        job = wait_job(daemon.client, job_id)
        assert job["status"] == "failed" and job["reason"].startswith(text), job["reason"]
        assert "kept" in job["reason"] or "frames" in job["reason"] or text == "camera"
        assert job["levels_done"] >= 2
        assert daemon.client.state()["hardware"][text.split(":")[0]].startswith("fault")
    finally:
        daemon.stop()
    assert audit_of(daemon.data) == []


def test_sigterm_cancels_the_scan_cleanly(tmp_path):
    daemon = Daemon(tmp_path, SLOW_STAGE)
    job_id = daemon.client.start_scan(PARAMS)
    for st in daemon.client.subscribe(timeout=20):
        if st["levels_done"] >= 2:
            break
    daemon.stop()
    store = Store(daemon.data)
    try:
        job = store.get_job(job_id)
        assert job["status"] == "cancelled" and not job["interrupted"]
        assert audit(store) == []
    finally:
        store.close()


def big_scan_folder(reference_scan, folder, frames=1500):
    """A scan folder of `frames` frames (hard links to one real frame), so that copying it
    into the daemon takes long enough to be killed in the middle of."""
    doc = json.loads((reference_scan / "scan.json").read_text())
    (folder / "frames").mkdir(parents=True)
    one = reference_scan / doc["frames"][0]["file"]
    doc["frames"] = []
    for i in range(frames):
        os.link(one, folder / "frames" / f"{i:05d}.png")
        doc["frames"].append({"file": f"frames/{i:05d}.png", "level_mm": round(2 + 0.01 * i, 3)})
    (folder / "scan.json").write_text(json.dumps(doc))
    return folder


def test_sigkill_mid_import_leaves_a_stray_folder_that_audit_counts_and_a_restart_removes(tmp_path):
    import threading

    ref, _ = service(tmp_path / "ref")
    try:
        ref_job = wait_final(ref, ref.start_scan(SCAN))
        assert ref_job["status"] == "done"
        source = big_scan_folder(ref.store.job_dir(ref_job["id"]) / "scan", tmp_path / "big")
    finally:
        ref.close()
    daemon = Daemon(tmp_path)
    jobs = daemon.data / "jobs"
    threading.Thread(
        target=lambda: pytest.raises(DeviceError, daemon.client.import_scan, source), daemon=True
    ).start()
    wait_until(
        lambda: [d for d in jobs.glob(".import-*") if len(list(d.glob("scan/frames/*"))) >= 100],
        60,
        what="the import to copy 100 frames",
        every=0.002,
    )
    daemon.kill()
    stray = list(jobs.glob(".import-*"))
    assert len(stray) == 1 and not list(jobs.glob("2*")), "killed after the copy was complete"
    found = audit_of(daemon.data)
    assert (
        len(found) == 1
        and found[0].startswith("jobs: imports left half-copied (removed when the daemon starts), ")
        and stray[0].name in found[0]
    ), found
    daemon = Daemon(tmp_path)  # start-up removes it
    try:
        assert list(jobs.glob(".import-*")) == []
        assert daemon.client.jobs() == []
    finally:
        daemon.stop()
    assert audit_of(daemon.data) == []
