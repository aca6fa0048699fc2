"""Shared bits of the daemon tests: a small fast scan on the fake bench."""

import numpy as np
from polling import wait_until

from appliance.daemon.processing import in_process
from appliance.daemon.service import BenchService
from appliance.sim.fakes import FakeBench

FINAL = ("done", "failed", "cancelled")
# the cone: a wall 3 mm high, then a 30-degree slope up to 23.2 mm; the first level is
# above its tip (a first frame showing the part makes the scan start higher, see levels.py)
# The seed method: our finishing toolpath takes minutes on a busy 2-core box,
# and these tests are about the daemon, not the CAM.
SCAN = {
    "name": "cone",
    "surface": "cone",
    "levels_to_mm": 24.0,
    "levels_from_mm": 6.0,
    "level_step_mm": 2.0,
    "settle_s": 0.0,
    "pipeline": "seed",
}


def service(tmp_path, faults=None, processor=in_process, **kw):
    bench = FakeBench("cone", faults=faults)
    return BenchService(tmp_path / "data", bench, processor=processor, panel_interval_s=0.02, **kw), bench


def wait_final(svc, job_id, timeout=60.0):
    """The job once it and the bench have finished (done, failed or cancelled), its thread
    included: the thread publishes the end, then closes the devices, and until it has a
    commissioning step that moves the stage is refused (it was, on a loaded CI box)."""

    def finished():
        job = svc.job(job_id)
        ended = job["status"] in FINAL and svc.state()["state"] in FINAL and not svc.scan_running()
        return job if ended else None

    return wait_until(finished, timeout, what=lambda: f"job {job_id} to finish: {svc.job(job_id)}")


def read_heightmap(path):
    """heightmap.csv -> the grid of z (NaN off the part)."""
    from appliance.outputs import read_heightmap_csv

    return np.asarray(read_heightmap_csv(path).z, float)
