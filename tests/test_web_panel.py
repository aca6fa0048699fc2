"""The bench page's machine panel and the job manager, on the daemon's real BenchService driving
the in-memory bench (sim.fakes): preview with the light, home, jog, go to a level, refused while
a scan runs; rename, delete, process again, sizes, thumbnails, downloads named for the job; the
ETA that learns from past jobs and covers processing; the stage-fault chip's text."""

import re
import time

import pytest
from polling import wait_until
from test_web_real_service import light_processor
from web_helpers import login

from appliance.daemon import rpc
from appliance.daemon.service import BenchService
from appliance.errors import DeviceError
from appliance.sim.fakes import FakeBench
from appliance.web import create_app

SCAN = {
    "name": "cone, left side",
    "surface": "cone",
    "levels_to_mm": 24.0,
    "levels_from_mm": 6.0,
    "level_step_mm": 2.0,
    "settle_s": 0.05,
}


@pytest.fixture(params=["in-process", "socket"])
def web(tmp_path, request):
    """The web on the daemon in-process, or as on the box: over the daemon's socket (rpc.py)."""
    factory = FakeBench("cone")
    svc = BenchService(tmp_path / "data", factory, processor=light_processor, panel_interval_s=0.05)
    server = client = None
    if request.param == "socket":
        server = rpc.serve(svc, tmp_path / "daemon.sock")
        client = rpc.BenchClient(tmp_path / "daemon.sock")
    app = create_app(client or svc, {"data_dir": str(tmp_path / "web")})
    app.config["TESTING"] = True
    c = app.test_client()
    h = {"X-CSRF-Token": login(c, app.config["FIRST_RUN_PASSWORD"])}
    yield c, h, svc, factory
    if client:
        client.close()
        server.shutdown()
        server.server_close()
    svc.close()


def finished_scan(c, h, svc, params=SCAN):
    job_id = c.post("/api/scan", json=params, headers=h).get_json()["job_id"]
    wait_until(lambda: svc.state()["state"] == "done", 30, what="the scan to be done", every=0.05)
    return job_id


def test_the_panel_previews_homes_jogs_and_goes_to_a_level_and_the_light_goes_off_after(web):
    c, h, svc, bench = web
    svc.manual.idle_s = 0.6
    st = c.post("/api/machine/preview", headers=h).get_json()
    assert st["open"] and st["light"] and not st["homed"]
    light = bench.last.light
    assert light.on
    assert c.get("/api/frame.jpg").status_code == 200  # the idle bench is not blind
    assert {"stage": "ok", "camera": "ok"}.items() <= c.get("/api/state").get_json()["hardware"].items()
    r = c.post("/api/machine/jog", json={"mm": 1}, headers=h)
    assert r.status_code == 400 and "home the stage first" in r.get_json()["error"]
    assert c.post("/api/machine/home", headers=h).get_json()["level_mm"] == 60.0
    for mm, level in ((10, 50.0), (1, 49.0), (0.1, 48.9), (-1, 49.9)):
        assert c.post("/api/machine/jog", json={"mm": mm}, headers=h).get_json()["level_mm"] == pytest.approx(
            level
        )
    assert c.post("/api/machine/jog", json={"mm": 3}, headers=h).status_code == 400  # not a jog step
    assert c.post("/api/machine/goto", json={"level_mm": 12.5}, headers=h).get_json()["level_mm"] == 12.5
    r = c.post("/api/machine/goto", json={"level_mm": -40}, headers=h)
    assert r.status_code == 400 and "outside the travel" in r.get_json()["error"]
    assert bench.last.stage.calls == [
        "home",
        "move 10.0000",
        "move 11.0000",
        "move 11.1000",
        "move 10.1000",
        "move 47.5000",
    ]
    assert c.get("/api/state").get_json()["manual"]["level_mm"] == 12.5
    time.sleep(1.2)  # nobody watching: light off, devices closed
    assert not light.on and c.get("/api/state").get_json()["manual"]["open"] is False


def test_the_panel_is_refused_while_a_scan_runs_and_a_scan_takes_the_devices_back(web):
    c, h, svc, bench = web
    c.post("/api/machine/preview", headers=h)
    panel_light = bench.last.light
    c.post("/api/scan", json={**SCAN, "settle_s": 0.3}, headers=h)
    wait_until(lambda: svc.state()["state"] == "scanning", what="the scan to start")
    assert not panel_light.on  # the panel's session was closed first
    for path, body in (
        ("/api/machine/home", None),
        ("/api/machine/jog", {"mm": 1}),
        ("/api/machine/goto", {"level_mm": 10}),
    ):
        r = c.post(path, json=body, headers=h)
        assert r.status_code == 409 and "a scan is running" in r.get_json()["error"], path
    busy = c.post("/api/machine/preview", headers=h).get_json()  # the scan's frames are the preview
    assert busy["open"] is False and "a scan is running" in busy["busy"]
    svc.cancel()


def test_the_job_manager_renames_sizes_thumbnails_names_downloads_reprocesses_and_deletes(web):
    c, h, svc, _ = web
    job_id = finished_scan(c, h, svc)
    listed = c.get("/api/jobs").get_json()["jobs"][0]
    assert listed["id"] == job_id and listed["name"] == "cone, left side" and listed["size_bytes"] > 1000
    page = c.get("/jobs").get_data(as_text=True)
    assert "cone, left side" in page and "took" in page and "thumb.png" in page
    assert re.search(r"· \d+(\.\d)? (kB|MB)</span>", page)  # its size on disk
    job_page = c.get(f"/jobs/{job_id}").get_data(as_text=True)
    assert (
        'id="reprocess-form"' in job_page
        and '<option value="mach3"' in job_page
        and "Delete this job" in job_page
    )
    thumb = c.get(f"/api/jobs/{job_id}/thumb.png")
    assert thumb.status_code == 200 and thumb.data[:8] == b"\x89PNG\r\n\x1a\n"
    r = c.get(f"/api/jobs/{job_id}/files/toolpath.gcode")
    stamp = "-".join(job_id.split("-")[:2])
    assert f"filename=cone-left-side-{stamp}-toolpath.gcode" in r.headers["Content-Disposition"]

    assert c.patch(f"/api/jobs/{job_id}", json={"name": "  "}, headers=h).status_code == 400
    assert c.patch(f"/api/jobs/{job_id}", json={"name": "mouse"}, headers=h).get_json()["name"] == "mouse"
    r = c.post(f"/api/jobs/{job_id}/reprocess", json={"settings": {"grid": -3}}, headers=h)
    assert r.status_code == 400 and r.get_json()["where"] == "grid"
    assert (
        c.post(f"/api/jobs/{job_id}/reprocess", json={"settings": {"grid": 30}}, headers=h).status_code == 202
    )
    wait_until(
        lambda: (svc.job(job_id)["status"], svc.state()["state"]) == ("done", "done"),
        30,
        what="the reprocessing to be done",
        every=0.05,
    )
    assert svc.job(job_id)["settings"]["grid"] == 30 and "toolpath.gcode" in svc.job(job_id)["outputs"]

    folder = svc.store.job_dir(job_id)
    assert c.delete(f"/api/jobs/{job_id}", headers=h).get_json() == {"ok": True}
    assert not folder.exists() and c.get(f"/api/jobs/{job_id}").status_code == 404
    assert c.get("/api/jobs").get_json()["jobs"] == []


def test_the_eta_learns_scanning_and_processing_from_past_jobs(web):
    c, h, svc, _ = web
    assert svc.state()["eta_processing_s"] is None  # a new box knows no processing time
    finished_scan(c, h, svc)
    learned = svc.job_times
    assert learned.count() == 1 and learned.per_level_s() > 0
    c.post("/api/scan", json={**SCAN, "settle_s": 0.2}, headers=h)
    seen = []
    end = time.monotonic() + 30
    while svc.state()["state"] != "done" and time.monotonic() < end:
        st = svc.state()
        seen.append((st["state"], st["eta_s"], st["eta_processing_s"]))
        time.sleep(0.02)
    scanning = [s for s in seen if s[0] == "scanning" and s[1] is not None]
    assert scanning and all(p is not None and eta >= p for _, eta, p in scanning)  # processing included
    assert scanning[0][1] > scanning[-1][1]  # and it counts down
    assert learned.count() == 2


def test_a_stage_fault_chip_reads_the_problem_not_a_cut_word(tmp_path):
    bench = FakeBench("cone", faults={"stage": {"unplug_after_moves": 0}})
    svc = BenchService(tmp_path / "data", bench, processor=light_processor, panel_interval_s=0.05)
    try:
        with pytest.raises(DeviceError):
            svc.home_stage()
        chip = svc.state()["hardware"]["stage"]
        assert chip == "fault: no reply from the controller (unplugged?)", chip
    finally:
        svc.close()


@pytest.mark.simavr
@pytest.mark.needs("simavr")
def test_the_panel_jogs_the_simulated_stage_firmware_under_simavr(tmp_path):
    """Through the web API to the real SerialStage and the stepper firmware under simavr: the
    position the firmware's STEP edges add up to is where the panel said it put the base."""
    from appliance.sim.fakes import SimulatedBenchFactory, small_rig

    factory = SimulatedBenchFactory("cone", small_rig(320, 240))
    svc = BenchService(tmp_path / "data", factory, processor=light_processor, panel_interval_s=0.05)
    try:
        app = create_app(svc, {"data_dir": str(tmp_path / "data")})
        app.config["TESTING"] = True
        c = app.test_client()
        h = {"X-CSRF-Token": login(c, app.config["FIRST_RUN_PASSWORD"])}
        at_home = svc.settings()["level_at_home_mm"]
        assert c.post("/api/machine/preview", headers=h).get_json()["light"] is True
        homed = c.post("/api/machine/home", headers=h).get_json()
        start = factory.bench.stage_position_mm()  # the firmware's home end of travel
        assert homed["homed"] and homed["level_mm"] == pytest.approx(at_home - start)
        for mm in (10, 1, 0.1, -1):
            c.post("/api/machine/jog", json={"mm": mm}, headers=h)
        assert factory.bench.stage_position_mm() == pytest.approx(start + 10.1, abs=1e-9)
        assert c.get("/api/state").get_json()["manual"]["level_mm"] == pytest.approx(at_home - start - 10.1)
        st = c.post("/api/machine/goto", json={"level_mm": at_home - 20.5}, headers=h).get_json()
        assert st["level_mm"] == pytest.approx(at_home - 20.5)
        assert factory.bench.stage_position_mm() == pytest.approx(20.5, abs=1e-9)
    finally:
        svc.close()
        factory.close()


def test_the_shown_eta_covers_processing_and_takes_the_processing_figure_when_it_starts():
    from appliance.web.eta import EtaSmoother

    now = [0.0]
    e = EtaSmoother(clock=lambda: now[0])

    def state(done, phase="scanning", eta=None):
        return {
            "state": phase,
            "job_id": "j",
            "levels_done": done,
            "levels_total": 20,
            "eta_s": eta,
            "eta_processing_s": 60.0,
        }

    e.update(state(0, eta=100.0))
    for i in range(1, 21):  # a level every 2 s: 40 s of scanning
        now[0] += 2.0
        shown = e.update(state(i))
        if i == 5:  # a quarter through the scan: 15 levels + processing left
            assert shown == pytest.approx(15 * 2.0 + 60.0, rel=0.1)
    now[0] += 1.0
    assert e.update(state(20, "processing", eta=60.0)) == 60.0  # a new phase is news, not jitter
    now[0] += 10.0
    assert e.update(state(20, "processing", eta=60.0)) == pytest.approx(50.0)  # and it counts down
    fresh = EtaSmoother(clock=lambda: now[0])  # a box with nothing learned yet
    fresh.update({**state(10), "eta_processing_s": None})
    now[0] += 2.0
    fresh.update({**state(11), "eta_processing_s": None})
    for _ in range(3):  # "processing", not a scan estimate counted down to 0 s
        now[0] += 1.0
        assert fresh.update({**state(20, "processing"), "eta_processing_s": None}) is None
