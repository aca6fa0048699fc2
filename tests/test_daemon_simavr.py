"""A whole scan through the daemon on the simulated bench: the real stepper
firmware under simavr behind the real SerialStage, and the renderer's
VirtualCamera looking at where the simulated stage really is."""
import json
import shutil

import numpy as np
import pytest

from appliance.daemon.processing import in_process
from appliance.daemon.recovery import audit
from appliance.daemon.service import BenchService
from appliance.cli import main as cli_main
from daemon_helpers import read_heightmap, wait_final

pytestmark = [pytest.mark.simavr,
              pytest.mark.skipif(shutil.which("avr-gcc") is None or shutil.which("simavr") is None,
                                 reason="needs gcc-avr and simavr (scripts/setup.sh)")]
PARAMS = {"name": "cone on simavr", "surface": "cone", "levels_to_mm": 24.0, "levels_from_mm": 6.0,
          "level_step_mm": 2.0, "settle_s": 0.0, "pipeline": "seed"}


@pytest.fixture(scope="module")
def factory():
    from appliance.sim.fakes import SimulatedBenchFactory, small_rig
    f = SimulatedBenchFactory("cone", small_rig(320, 240))
    yield f
    f.close()


@pytest.fixture(scope="module")
def reference(factory, tmp_path_factory):
    svc = BenchService(tmp_path_factory.mktemp("simref") / "data", factory, processor=factory.processor(in_process))
    try:
        job = wait_final(svc, svc.start_scan(PARAMS), timeout=120)
        return svc, job
    finally:
        svc.close()


def test_a_whole_scan_on_simavr_matches_inkslice_process(reference, factory, tmp_path):
    svc, job = reference
    assert job["status"] == "done", job["reason"]
    job_dir = svc.store.job_dir(job["id"])
    scan = json.loads((job_dir / "scan/scan.json").read_text())
    # nominal levels come from the position the firmware reports: exact steps of 1/1600 mm
    assert [f["level_mm"] for f in scan["frames"]] == [24.0 - 2 * k for k in range(10)]
    # the stage really went there: the last level's position, counted from STEP edges
    at_home = job["settings"]["level_at_home_mm"]
    assert abs(factory.bench.stage_position_mm() - (at_home - 6.0)) < 1e-9
    assert cli_main(["process", str(job_dir / "scan"), "-o", str(tmp_path / "cli"), "--pipeline", "seed"]) == 0
    for name in ("heightmap.csv", "toolpath.gcode"):
        assert (tmp_path / "cli" / name).read_bytes() == (job_dir / name).read_bytes(), name
    report = json.loads((job_dir / "report.json").read_text())
    assert report["truth"] == "cone"
    assert factory.last.light.on is False


@pytest.mark.slow
def test_an_mcu_reset_mid_scan_stops_the_job_and_resume_finishes_it(reference, factory, tmp_path):
    ref_svc, ref_job = reference
    ref_map = read_heightmap(ref_svc.store.job_dir(ref_job["id"]) / "heightmap.csv")
    svc = BenchService(tmp_path / "data", factory, processor=in_process)
    try:
        job_id = svc.start_scan(PARAMS)
        for st in svc.subscribe(timeout=60):
            if st["levels_done"] >= 3:
                factory.bench.reset_mcu()
                break
        job = wait_final(svc, job_id, timeout=120)
        assert job["status"] == "failed", job
        assert job["reason"].startswith("stage") and "reset" in job["reason"], job["reason"]
        assert 3 <= job["levels_done"] < 10
        assert factory.last.light.on is False
        assert svc.state()["hardware"]["stage"].startswith("fault")
        assert audit(svc.store) == []
        svc.resume(job_id)
        job = wait_final(svc, job_id, timeout=120)
        assert job["status"] == "done", job["reason"]
        got = read_heightmap(svc.store.job_dir(job_id) / "heightmap.csv")
        assert np.nanmax(np.abs(got - ref_map)) <= 0.005
    finally:
        svc.close()

