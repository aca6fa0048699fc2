"""Commissioning on the daemon (daemon/commissioning.py) with the simulated bench's devices:
every step measured, the calibration then in every scan.json and named in the report; a
scan without it warned about; every step cancellable with the bench free afterwards; the
whole commissioning carried to a fresh box as one file; an ink change marking results stale."""

import json

import numpy as np
import pytest
from daemon_helpers import wait_final
from polling import wait_until

from appliance.daemon.processing import in_process
from appliance.daemon.service import BenchService
from appliance.errors import InkSliceError, SettingError
from appliance.sim.fakes import FakeBench

TRUE_LEVEL_ZERO = 57.3  # the bench's truth; the daemon's setting starts at 60
# a short scan of the cone with the seed method (fast): these tests are about what
# goes into scan.json and the report, not the science. It starts above the cone's tip (23.2 mm,
# with the ink 2.7 mm below the setting's level): a first frame showing the part would make the
# scan start higher (daemon/levels.py)
SCAN = {
    "name": "cone",
    "levels_to_mm": 28.0,
    "levels_from_mm": 10.0,
    "level_step_mm": 2.0,
    "settle_s": 0.0,
    "pipeline": "seed",
}
SHORT = {"levels_to_mm": 28.0, "levels_from_mm": 22.0}


def box(tmp_path, name="data"):
    bench = FakeBench("cone", level_at_home_mm=TRUE_LEVEL_ZERO)
    return BenchService(tmp_path / name, bench, processor=in_process, panel_interval_s=0.02), bench


def step(c, sid):
    return next(s for s in c["steps"] if s["id"] == sid)


def commission_everything(svc):
    svc.commission("level_zero", "start")
    c = svc.commission("level_zero", "measure")
    assert c["active"]["stage"] == "check" and c["active"]["holds_bench"]
    svc.commission("level_zero", "accept")
    svc.commission("camera", "start")
    for _ in range(4):
        svc.commission("camera", "view")
    c = svc.commission("camera", "plane")
    assert c["active"]["detected"]["views"] == 4
    svc.commission("camera", "accept")
    svc.commission("tank", "enter", {"width_mm": 150, "depth_mm": 150})
    svc.commission("meniscus", "start", {"diameter_mm": 25.4})
    c = svc.commission("meniscus", "scan")
    job = wait_final(svc, c["active"]["job_id"], timeout=300)
    assert job["status"] == "done", job["reason"]
    c = svc.commissioning()
    assert c["active"]["stage"] == "check", c["active"]
    return svc.commission("meniscus", "accept")


@pytest.fixture(scope="module")
def commissioned(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("commissioned")
    svc, bench = box(tmp)
    try:
        c = commission_everything(svc)
        job = wait_final(svc, svc.start_scan(SCAN))
        yield svc, bench, c, job
    finally:
        svc.close()


def test_every_step_is_measured_and_stored_with_its_date(commissioned):
    svc, bench, c, _ = commissioned
    assert [s["id"] for s in c["steps"]] == ["level_zero", "camera", "tank", "meniscus"]
    assert all(s["status"] == "done" and s["date"] for s in c["steps"]), c["steps"]
    assert c["active"] is None
    # level zero: where the base top meets the ink, found with the stage and the camera
    lz = step(c, "level_zero")["result"]["level_at_home_mm"]
    assert abs(lz - TRUE_LEVEL_ZERO) <= 0.01 and svc.settings()["level_at_home_mm"] == lz
    cam = step(c, "camera")["result"]
    assert cam["views"] == 4 and cam["plane_rms_mm"] < 0.1 and "camera" not in cam
    assert step(c, "tank")["result"]["figure"] == "150 x 150 mm = 22500 mm²"
    men = step(c, "meniscus")["result"]
    ref = men["reference"]
    assert ref["kind"] == "ball" and ref["diameter_mm"] == 25.4
    # the fake camera draws no meniscus (it renders the level curve itself): the fit finds none
    assert men["capillary_length_mm"] < 0.5, men
    # where the simulated hand put the ball (sim/staging.py BALL_AT), found from the scan
    assert np.allclose(ref["centre_mm"], (48.0, 52.5), atol=0.5), ref
    assert ref["mean_abs_error_mm"] < 0.3 and ref["cells"] > 20, ref
    # what was asked of the operator, in order, and the base cleared after each step
    kinds = [r.kind for r in bench.panel.operator.requests]
    assert kinds[0] == "empty" and "board_views" in kinds and "board_flat" in kinds and "reference" in kinds
    assert kinds[-1] == "clear" and bench.placement is None


def test_the_scan_carries_the_calibration_in_force(commissioned):
    svc, _, c, job = commissioned
    assert job["status"] == "done", job["reason"]
    doc = json.loads(svc.job_file(job["id"], "scan/scan.json").read_text())
    stored = svc.store.calibrations()
    camera_row = next(r for r in stored if r.get("kind") == "camera")
    assert doc["camera"]["homography"] == camera_row["camera"]["homography"]
    # no overflow said: the ink falls under the camera, and processing moves each frame to it
    assert doc["tank"] == {"inner_area_mm2": 22500.0, "surface_falls": True}
    men = step(c, "meniscus")["result"]
    assert doc["meniscus"]["capillary_length_mm"] == men["capillary_length_mm"]
    # and how much the contact line's own bend counts (surface/meniscus.py), measured with them
    assert doc["meniscus"]["contact_line_curvature"] == men["contact_line_curvature"]
    assert doc["level_at_home_mm"] == step(c, "level_zero")["result"]["level_at_home_mm"]
    used = doc["calibration"]
    for sid in ("camera", "tank", "meniscus", "level_zero"):
        assert used[sid]["date"] == step(c, sid)["date"], sid
    report = json.loads(svc.job_file(job["id"], "report.json").read_text())
    assert report["calibration"]["warnings"] == []
    # the seed method (these tests' choice for speed) corrects neither effect
    assert "switched off" in report["calibration"]["used"]["tank"]
    md = svc.job_file(job["id"], "report.md").read_text()
    assert "## Calibration" in md and "commissioned camera (measured, " in md
    # `inkslice process` on the folder (our pipeline) corrects with what scan.json carries
    from appliance.process import process

    ours = process(svc.job_file(job["id"], "scan/scan.json").parent, truth=False)
    assert ours.diagnostics["corrections"] == {"displacement_tank_area_mm2": 22500.0, "meniscus": True}
    assert (
        ours.calibration["warnings"] == []
        and "meniscus: capillary length" in ours.calibration["used"]["meniscus"]
    )


def test_a_scan_without_commissioning_gets_warnings(tmp_path):
    svc, _ = box(tmp_path)
    try:
        job = wait_final(
            svc,
            svc.start_scan(
                {**SCAN, "pipeline": "inkslice", "levels_to_mm": 24.0, "level_at_home_mm": TRUE_LEVEL_ZERO}
            ),
            timeout=300,
        )
        assert job["status"] == "done", job["reason"]
        doc = json.loads(svc.job_file(job["id"], "scan/scan.json").read_text())
        assert "tank" not in doc and "meniscus" not in doc
        assert doc["calibration"]["level_zero"]["method"] == "setting"
        warnings = json.loads(svc.job_file(job["id"], "report.json").read_text())["calibration"]["warnings"]
        text = " | ".join(warnings)
        for expected in (
            "no meniscus calibration was used",
            "no tank area calibration was used",
            "the camera was not commissioned",
            "level zero was not measured",
        ):
            assert expected in text, text
        assert "no meniscus calibration was used" in svc.job_file(job["id"], "report.md").read_text()
    finally:
        svc.close()


CANCEL_POINTS = [
    ("level_zero", []),
    ("level_zero", ["measure"]),
    ("camera", []),
    ("camera", ["view"]),
    ("camera", ["view", "view", "view", "plane"]),
    ("meniscus", []),
    ("meniscus", ["scan"]),
]


def test_cancel_at_each_step_then_a_scan_starts(tmp_path):
    svc, bench = box(tmp_path)
    try:
        svc.commission("tank", "enter", {"area_mm2": 20000})  # enter: nothing to cancel
        for sid, actions in CANCEL_POINTS:
            svc.commission(sid, "start")
            for a in actions:
                svc.commission(sid, a)
            if sid != "meniscus":
                # a step holding the devices refuses scans, naming the way out
                with pytest.raises(SettingError, match=f"commissioning/{sid}/cancel"):
                    svc.start_scan(SCAN)
            c = svc.commission(sid, "cancel")
            assert c["active"] is None and bench.placement is None, (sid, actions)
            assert step(c, sid)["status"] == "missing", (sid, actions)
            job = wait_final(svc, svc.start_scan({**SCAN, **SHORT}), timeout=180)
            assert job["status"] == "done", (sid, actions, job["reason"])
        # the meniscus scan cancelled mid-way is a cancelled job, nothing stored
        refs = [j for j in svc.jobs() if j["params"].get("reference")]
        assert len(refs) == 1 and refs[0]["status"] == "cancelled"
        assert svc.settings()["level_at_home_mm"] == 60.0
        assert [r["kind"] for r in svc.store.calibrations()] == ["tank"]
    finally:
        svc.close()


def test_skip_records_the_step_as_skipped_and_keeps_what_was_in_force(tmp_path):
    svc, _ = box(tmp_path)
    try:
        svc.commission("tank", "enter", {"area_mm2": 20000})
        svc.commission("camera", "start")
        c = svc.commission("camera", "skip")
        assert c["active"] is None and step(c, "camera")["status"] == "skipped"
        c = svc.commission("tank", "skip")
        assert step(c, "tank")["status"] == "done" and step(c, "tank")["result"]["area_mm2"] == 20000
    finally:
        svc.close()


def test_the_guided_calibration_and_a_commissioning_step_never_hold_the_bench_together(tmp_path):
    svc, _ = box(tmp_path)
    try:
        svc.commission("camera", "start")
        with pytest.raises(SettingError, match="commissioning/camera/cancel"):
            svc.calibrate("home")
        svc.commission("camera", "cancel")
        svc.calibrate("home")
        with pytest.raises(SettingError, match="guided calibration holds the bench"):
            svc.commission("level_zero", "start")
        svc.calibrate("cancel")
        assert svc.commission("level_zero", "start")["active"]["holds_bench"]
    finally:
        svc.close()


def test_skipping_the_meniscus_during_its_scan_cancels_the_scan(tmp_path):
    svc, _ = box(tmp_path)
    try:
        svc.commission("meniscus", "start", {"diameter_mm": 25.4})
        job_id = svc.commission("meniscus", "scan")["active"]["job_id"]
        c = svc.commission("meniscus", "skip")
        assert c["active"] is None and step(c, "meniscus")["status"] == "skipped"
        assert wait_final(svc, job_id)["status"] == "cancelled"
        job = wait_final(svc, svc.start_scan({**SCAN, **SHORT}))
        assert job["status"] == "done", job["reason"]
    finally:
        svc.close()


def test_export_then_import_on_a_fresh_box_gives_the_same_commissioning(commissioned, tmp_path):
    svc, *_ = commissioned
    doc = json.loads(json.dumps(svc.export_commissioning()))  # as the file carries it
    fresh, _ = box(tmp_path, "fresh")
    try:
        with pytest.raises(SettingError, match="not a commissioning export"):
            fresh.import_commissioning({"format": "something else"})
        broken = json.loads(json.dumps(doc))
        del broken["results"]["meniscus"]["result"]["contact_angle_deg"]
        with pytest.raises(SettingError, match="meniscus: contact_angle_deg is missing"):
            fresh.import_commissioning(broken)
        assert fresh.store.calibrations() == []  # a refused file changes nothing
        fresh.import_commissioning(doc)
        a, b = svc.commissioning(), fresh.commissioning()
        strip = lambda c: [{k: v for k, v in s.items() if k != "method"} for s in c["steps"]]
        assert strip(a) == strip(b)
        assert fresh.settings()["level_at_home_mm"] == svc.settings()["level_at_home_mm"]
        assert fresh.export_commissioning()["results"] == doc["results"]
    finally:
        fresh.close()


def test_an_ink_change_makes_meniscus_and_level_zero_stale(tmp_path):
    svc, _ = box(tmp_path)
    try:
        svc.commission("level_zero", "enter", {"level_at_home_mm": TRUE_LEVEL_ZERO})
        svc.commission("tank", "enter", {"area_mm2": 22500})
        c = svc.ink_changed()
        assert c["ink_changed"] and step(c, "level_zero")["status"] == "stale"
        assert step(c, "tank")["status"] == "done"
        job = wait_final(svc, svc.start_scan(SCAN))
        warnings = json.loads(svc.job_file(job["id"], "report.json").read_text())["calibration"]["warnings"]
        assert any("level zero calibration" in w and "older than the last ink change" in w for w in warnings)
        c = svc.commission("level_zero", "enter", {"level_at_home_mm": TRUE_LEVEL_ZERO})
        assert step(c, "level_zero")["status"] == "done"
    finally:
        svc.close()


def test_the_web_process_commissions_over_the_daemons_socket(tmp_path):
    """The web server talks to the daemon over its socket (rpc.BenchClient): the same calls."""
    from appliance.daemon import rpc

    svc, bench = box(tmp_path)
    server = rpc.serve(svc, tmp_path / "daemon.sock")
    client = rpc.BenchClient(tmp_path / "daemon.sock")
    try:
        c = client.commission("tank", "enter", {"width_mm": 140, "depth_mm": 150.5})
        assert step(c, "tank")["result"]["figure"] == "140 x 150.5 mm = 21070 mm²"
        with pytest.raises(SettingError, match="possible: start, enter, cancel, skip"):
            client.commission("level_zero", "measure")
        c = client.commission("level_zero", "start")
        assert c["active"]["holds_bench"] and c["active"]["prompt"].startswith("Take everything off the base")
        assert svc.state()["message"] == c["active"]["prompt"]  # the page says it, the display in short
        wait_until(
            lambda: bench.panel.display.lines[:3] == ["SETUP LEVEL 0", "EMPTY THE BASE", "see the phone"],
            what="the display's set-up prompt",
        )
        assert client.commission("level_zero", "cancel")["active"] is None
        doc = client.export_commissioning()
        assert set(doc["results"]) == {"tank"} and client.ink_changed()["ink_changed"]
        assert step(client.import_commissioning(doc), "tank")["status"] == "done"
        assert client.commissioning() == svc.commissioning()
    finally:
        client.close()
        server.shutdown()
        server.server_close()
        svc.close()


def test_a_step_that_cannot_start_leaves_nothing_held(tmp_path):
    bench = FakeBench("cone", faults={"stage": {"unplug_after_moves": 0}})
    svc = BenchService(tmp_path / "data", bench, processor=in_process, panel_interval_s=0.02)
    try:
        for sid in ("level_zero", "camera"):
            with pytest.raises(InkSliceError, match="unplugged"):
                svc.commission(sid, "start")
            c = svc.commissioning()
            assert c["active"] is None and bench.placement is None, sid
            assert step(c, sid)["status"] == "missing"
    finally:
        svc.close()


def test_the_tank_step_says_whether_the_ink_falls_under_the_camera():
    """Unless an overflow or a reservoir holds the ink where the camera was calibrated on it, the
    ink falls as the part comes out, and processing must move each frame's points to it."""
    from appliance.daemon.measurements import tank_result
    from appliance.errors import SettingError

    assert tank_result({"area_mm2": 22500})["surface_falls"] is True
    held = tank_result({"width_mm": 150, "depth_mm": 150, "level_held": True})
    assert held["surface_falls"] is False and held["area_mm2"] == 22500.0
    assert held["figure"] == "150 x 150 mm = 22500 mm², the ink's level held by an overflow"
    with pytest.raises(SettingError, match="level_held"):
        tank_result({"area_mm2": 22500, "level_held": "yes"})
