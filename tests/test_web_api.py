"""The JSON API on the daemon's BenchService driving the in-memory bench (a cone): scans, jobs,
downloads, settings, live view, docs."""

import io
import json
import math
import re
import time
import zipfile

import numpy as np
import pytest
from web_helpers import NOTE, QUICK, login, make_app, wait_state

from appliance.sim.surfaces import get as get_surface
from appliance.web.eta import EtaSmoother


@pytest.fixture
def client(tmp_path):
    app, svc = make_app(tmp_path)
    c = app.test_client()
    csrf = login(c, app.config["FIRST_RUN_PASSWORD"])
    c.environ_base["HTTP_X_CSRF_TOKEN"] = csrf  # every request of this client carries it
    yield c, svc, app
    svc.close()


def test_openapi_describes_exactly_the_api_routes(client):
    c, svc, app = client
    doc = c.get("/api/openapi.json").get_json()
    assert doc["openapi"].startswith("3.")
    documented = {(m.upper(), p) for p, ops in doc["paths"].items() for m in ops}
    served = set()
    for rule in app.url_map.iter_rules():
        if not rule.rule.startswith("/api/") or rule.endpoint == "pages.api_docs":
            continue
        path = re.sub(r"<(?:\w+:)?(\w+)>", r"{\1}", rule.rule[len("/api") :])
        for m in rule.methods - {"HEAD", "OPTIONS"}:
            if m == "POST" and rule.endpoint == "api.patch_settings":
                continue  # POST is an alias of PATCH for HTML forms; documented as PATCH
            served.add((m, path))
    assert served == documented, served ^ documented


def test_a_scan_from_start_to_downloads(client):
    c, svc, app = client
    assert c.get("/api/state").get_json()["state"] == "idle"
    r = c.post("/api/scan", json={"level_step_mm": 1.0})
    assert r.status_code == 201
    job_id = r.get_json()["job_id"]
    assert c.post("/api/scan", json={}).status_code == 409  # one at a time
    st = wait_state(c, {"done"})
    # 24 mm down to 6 mm in 1 mm steps: 19 levels, every one of them captured
    assert st["job_id"] == job_id and st["levels_done"] == st["levels_total"] == 19
    jobs = c.get("/api/jobs").get_json()["jobs"]
    assert jobs[0]["id"] == job_id
    info = c.get(f"/api/jobs/{job_id}").get_json()
    assert {"toolpath.gcode", "heightmap.csv", "report.json", "error_inkslice_fit.png"} <= set(
        info["outputs"]
    )
    for name in info["outputs"]:
        r = c.get(f"/api/jobs/{job_id}/files/{name}")
        assert r.status_code == 200
        assert r.data == svc.job_file(job_id, name).read_bytes(), name
        assert r.headers["Content-Disposition"].startswith("attachment")
    assert (
        c.get(f"/api/jobs/{job_id}/files/error_inkslice_fit.png?inline=1")
        .headers["Content-Disposition"]
        .startswith("inline")
    )
    z = zipfile.ZipFile(io.BytesIO(c.get(f"/api/jobs/{job_id}/archive.zip").data))
    frames = [f"scan/{f['file']}" for f in json.loads(z.read(f"{job_id}/scan/scan.json"))["frames"]]
    assert len(frames) == 19  # the outputs, the record, and the scan itself: scan.json and every frame
    assert sorted(n.split("/", 1)[1] for n in z.namelist()) == sorted(
        info["outputs"] + ["job.json", "scan/scan.json"] + frames
    )
    assert z.read(f"{job_id}/toolpath.gcode") == svc.job_file(job_id, "toolpath.gcode").read_bytes()
    assert c.get(f"/api/jobs/{job_id}/files/nothere.gcode").status_code == 404
    assert c.get("/api/jobs/19990101-000000-0000").status_code == 404
    page = c.get(f"/jobs/{job_id}").get_data(as_text=True)
    assert "0.0722" in page and 'id="view3d"' in page  # the report's statistics, the 3D view
    assert f"<li>{NOTE}</li>" in page  # and what the processing has to say (a pocket that held ink)
    assert all(f'data-file="{name}"' in page for name in info["outputs"])  # every download


def test_cancel_and_resume(tmp_path):
    app, svc = make_app(tmp_path, fast=False)
    c = app.test_client()
    c.environ_base["HTTP_X_CSRF_TOKEN"] = login(c, app.config["FIRST_RUN_PASSWORD"])
    job_id = c.post("/api/scan", json={}).get_json()["job_id"]
    wait_state(c, {"scanning"})
    time.sleep(0.4)
    assert c.post("/api/scan/cancel").get_json()["state"] == "cancelled"
    done_at_cancel = c.get(f"/api/jobs/{job_id}").get_json()["levels_done"]
    assert 0 < done_at_cancel < 41
    assert c.post("/api/jobs/19990101-000000-0000/resume").status_code == 404
    assert c.post(f"/api/jobs/{job_id}/resume").status_code == 201
    st = wait_state(c, {"scanning"})
    assert st["levels_done"] >= done_at_cancel  # resumed, not restarted
    c.post("/api/scan/cancel")
    svc.close()


def test_settings_are_validated_by_the_service_and_name_the_bad_key(client):
    c, svc, app = client
    s = c.get("/api/settings").get_json()
    assert s["dialect"] == "linuxcnc"
    r = c.patch("/api/settings", json={"cutter_diameter_mm": -3})
    assert r.status_code == 400 and r.get_json()["where"] == "cutter_diameter_mm"
    r = c.patch("/api/settings", json={"dialect": "heidenhain"})
    assert r.status_code == 400 and r.get_json()["where"] == "dialect"
    assert c.patch("/api/settings", data="not json", content_type="application/json").status_code == 400
    r = c.patch("/api/settings", json={"dialect": "grbl", "cutter_diameter_mm": 3.175})
    assert r.status_code == 200 and r.get_json()["dialect"] == "grbl"
    assert c.get("/api/settings").get_json()["cutter_diameter_mm"] == 3.175
    assert c.post("/api/scan", json={"level_step_mm": 0}).status_code == 400


def test_live_view_frame_and_heightmap_and_sse(client):
    c, svc, app = client
    assert c.get("/api/frame.jpg").status_code == 204
    assert c.get("/api/heightmap/live").status_code == 204
    c.post("/api/scan", json={})
    wait_state(c, {"done"})
    r = c.get("/api/frame.jpg")
    assert r.status_code == 200 and r.data[:2] == b"\xff\xd8"
    assert r.headers["X-Level-mm"] == str(QUICK["levels_from_mm"])  # the scan's last level
    assert c.get("/api/frame.jpg", headers={"If-None-Match": r.headers["ETag"]}).status_code == 304
    hm = c.get("/api/heightmap/live").get_json()
    cone = get_surface("cone")
    # one cell of the coarse map spans this much of the cone's 30-degree slope
    cell_rise = (hm["x"][1] - hm["x"][0]) * math.tan(math.radians(30))
    seen = 0
    for j, y in enumerate(hm["y"]):
        for i, x in enumerate(hm["x"]):
            z = hm["z"][j][i]
            if z is not None:  # each cell holds the highest level at which it stood above the ink
                seen += 1
                true = float(cone.height(np.array(x), np.array(y)))
                assert -cell_rise <= true - z < QUICK["level_step_mm"] + cell_rise
    assert seen > 100
    app.extensions["inkslice"]["config"]["sse_max_s"] = 0.6
    body = c.get("/api/events").get_data(as_text=True)
    assert body.startswith("retry: 1000")
    events = re.findall(r"event: (\w+)\ndata: (.*)\n", body)
    kinds = [k for k, _ in events]
    assert "state" in kinds and "frame" in kinds
    st = json.loads(dict(events)["state"])
    assert st["state"] == "done" and "eta_display_s" in st


def test_calibration_steps(client):
    c, svc, app = client  # the simulated hand lays the printed board on the base when asked
    cal = c.get("/api/calibration").get_json()
    assert [s["id"] for s in cal["steps"]] == ["home", "target", "detect", "accept"] and cal["step"] == 0
    assert c.post("/api/calibration/detect").status_code == 400  # out of order
    c.post("/api/calibration/home")
    c.post("/api/calibration/target")
    cal = c.post("/api/calibration/detect").get_json()
    assert cal["detected"]["corners"] == 9 * 6  # every inner corner of the board
    assert c.get("/api/frame.jpg").status_code == 200  # the preview


def test_usb_export_switched_off_in_the_web_hides_the_sticks_and_refuses_a_copy(tmp_path):
    """serve --no-usb; the copy itself is the daemon's (test_web_real_service.py)."""
    app, svc = make_app(tmp_path, usb=False)
    c = app.test_client()
    c.environ_base["HTTP_X_CSRF_TOKEN"] = login(c, app.config["FIRST_RUN_PASSWORD"])
    c.post("/api/scan", json={})
    job_id = wait_state(c, {"done"})["job_id"]
    assert c.get("/api/usb").get_json() == {"available": False, "sticks": []}
    r = c.post(f"/api/jobs/{job_id}/usb", json={})
    assert r.status_code == 501 and r.get_json()["where"] == "usb"
    svc.close()


# -- the ETA -----------------------------------------------------------------------------


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def st(done, total=100, state="scanning", eta=None, job="j"):
    return {"state": state, "job_id": job, "levels_done": done, "levels_total": total, "eta_s": eta}


def test_eta_converges_on_a_steady_scan_and_counts_down_between_levels():
    clk = Clock()
    e = EtaSmoother(clock=clk)
    e.update(st(0, state="homing", eta=999))
    clk.t = 5
    e.update(st(0))
    shown = []
    for i in range(1, 60):
        clk.t += 2.0  # a level every 2 s
        shown.append(e.update(st(i)))
        # asking often between levels only counts down, it does not re-estimate
        clk.t += 1.0
        a = e.update(st(i))
        b = e.update(st(i))
        assert a == b and a == pytest.approx(shown[-1] - 1.0, abs=0.11)
        clk.t -= 1.0
    assert shown[-1] == pytest.approx((100 - 59) * 2.0, rel=0.05)


def test_eta_does_not_jump_on_one_slow_level():
    clk = Clock()
    e = EtaSmoother(clock=clk)
    e.update(st(0))
    for i in range(1, 30):
        clk.t += 2.0
        before = e.update(st(i))
    clk.t += 30.0  # one level takes 15 x longer (a re-focus, a bubble)
    after = e.update(st(30))
    counted = before - 30.0
    assert after - counted <= max(3.0, 0.1 * counted) + 0.1
    assert after < before  # it never goes back up above where it was


def test_eta_resets_for_a_new_job_and_is_zero_when_done():
    clk = Clock()
    e = EtaSmoother(clock=clk)
    e.update(st(0, job="a"))
    clk.t += 1
    e.update(st(1, job="a"))
    assert e.update(st(100, state="done", job="a")) == 0.0
    assert e.update(st(0, state="homing", job="b", eta=50)) == 50.0
    assert e.update({"state": "idle"}) is None


def test_live_streams_are_capped_and_the_rest_get_503(tmp_path):
    app, svc = make_app(tmp_path, max_streams=2, sse_max_s=5)
    c = app.test_client()
    c.environ_base["HTTP_X_CSRF_TOKEN"] = login(c, app.config["FIRST_RUN_PASSWORD"])
    open_streams = [c.get("/api/events", buffered=False) for _ in range(2)]
    for r in open_streams:
        assert r.status_code == 200
        assert next(iter(r.response)).startswith(b"retry:")
    third = c.get("/api/events")
    assert third.status_code == 503 and "poll" in third.get_json()["error"]
    assert c.get("/api/state").status_code == 200  # everything else still answers
    open_streams[0].close()  # a stream that ends frees its slot
    again = c.get("/api/events", buffered=False)
    assert again.status_code == 200
    again.close()
    open_streams[1].close()
    svc.close()
