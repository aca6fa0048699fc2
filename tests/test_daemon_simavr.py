"""A whole scan through the daemon on the simulated bench: the real stepper
firmware under simavr behind the real SerialStage, and the renderer's
VirtualCamera looking at where the simulated stage really is."""

import json

import numpy as np
import pytest
from daemon_helpers import read_heightmap, wait_final

from appliance.cli import main as cli_main
from appliance.daemon.processing import in_process
from appliance.daemon.recovery import audit
from appliance.daemon.service import BenchService

pytestmark = [
    pytest.mark.simavr,
    pytest.mark.needs("simavr"),
]
PARAMS = {
    "name": "cone on simavr",
    "surface": "cone",
    "levels_to_mm": 24.0,
    "levels_from_mm": 6.0,
    "level_step_mm": 2.0,
    "settle_s": 0.0,
    "pipeline": "seed",
}


@pytest.fixture(scope="module")
def factory():
    from appliance.sim.fakes import SimulatedBenchFactory, small_rig

    f = SimulatedBenchFactory("cone", small_rig(320, 240))
    yield f
    f.close()


@pytest.fixture(scope="module")
def reference(factory, tmp_path_factory):
    svc = BenchService(
        tmp_path_factory.mktemp("simref") / "data", factory, processor=factory.processor(in_process)
    )
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
    assert [f["level_mm"] for f in scan["frames"] if "refines" not in f] == [24.0 - 2 * k for k in range(10)]
    # the stage really went there: the last level's position, counted from STEP edges
    at_home = job["settings"]["level_at_home_mm"]
    assert abs(factory.bench.stage_position_mm() - (at_home - 6.0)) < 1e-9
    assert (
        cli_main(["process", str(job_dir / "scan"), "-o", str(tmp_path / "cli"), "--pipeline", "seed"]) == 0
    )
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


# the plateau: flat at 25 mm inside r < 22 mm. Its top comes out of the ink all at once
# between the levels 26 and 24; the runner goes back into that step and bisects it.
PLATEAU = {
    "name": "plateau on simavr",
    "surface": "plateau",
    "levels_to_mm": 26.0,
    "levels_from_mm": 20.0,
    "level_step_mm": 2.0,
    "settle_s": 0.0,
    "pipeline": "seed",
}


def test_a_face_out_at_once_is_bisected_by_going_back_into_its_step(factory, tmp_path):
    from appliance.scanfile import load_scan, read_frame
    from appliance.vision.part import find_part
    from appliance.vision.refine import face_bracket, mask_pixel_mm, surfaced_faces

    svc = BenchService(tmp_path / "data", factory, processor=factory.processor(in_process))
    try:
        job = wait_final(svc, svc.start_scan(PLATEAU), timeout=180)
        assert job["status"] == "done", job["reason"]
        scan = load_scan(svc.store.job_dir(job["id"]) / "scan")
    finally:
        svc.close()
    plan = [f for f in scan.frames if "refines" not in f.extra]
    extra = [f for f in scan.frames if "refines" in f.extra]
    assert [f.level_mm for f in plan] == [26.0, 24.0, 22.0, 20.0]
    # right after the frame that showed the face, marked with the step, at the levels the stage
    # reached (exact 1/1600 mm steps): a bisection of the 2 mm step down to 0.0625 mm
    assert scan.frames[2 : 2 + len(extra)] == extra and len(extra) == 5
    assert all(f.extra["refines"] == [26.0, 24.0] and 24.0 < f.level_mm < 26.0 for f in extra)
    assert extra[0].level_mm == 25.0
    # read back from the frames alone, the face is now known to within 0.1 mm
    part = {f.file: find_part(read_frame(scan, f), scan.camera, f.level_mm) for f in scan.frames}
    faces = surfaced_faces(
        part[plan[0].file], part[plan[1].file], mask_pixel_mm(scan.camera, part[plan[1].file].shape)
    )
    assert len(faces) == 1
    lo, hi = face_bracket(faces[0], 26.0, 24.0, [(f.level_mm, part[f.file]) for f in extra])
    assert hi - lo <= 0.1 and 24.5 < lo < 25.5
    assert job["levels_done"] == len(scan.frames) == 9
