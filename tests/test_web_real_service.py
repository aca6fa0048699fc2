"""The web UI on the daemon team's real BenchService (fake devices), in-process and over its socket."""

import io
import json
import zipfile

import pytest
from polling import wait_until
from web_helpers import light_processor, login, wait_state

from appliance.daemon import rpc
from appliance.daemon.service import BenchService
from appliance.hw.usb import UsbExporter
from appliance.sim.fakes import FakeBench
from appliance.web import create_app

SCAN = {
    "name": "cone",
    "surface": "cone",
    "levels_to_mm": 24.0,
    "levels_from_mm": 6.0,
    "level_step_mm": 2.0,
    "settle_s": 0.0,
}


class ChessboardBench(FakeBench):
    """The fake bench with the printed calibration board on its base: the camera sees a
    9 x 6 chessboard of 10 mm squares at 4 px/mm, its first inner corner at pixel (150, 130)."""

    PX_PER_MM, ORIGIN = 4.0, (150.0, 130.0)

    def __init__(self, surface, **kw):
        from appliance.sim.fakes import small_rig

        super().__init__(surface, rig=small_rig(640, 480), **kw)  # the frames' size: the camera model's

    def open(self, settings, params):
        import numpy as np

        devices = super().open(settings, params)
        img = np.full((480, 640, 3), 255, np.uint8)
        s, (u0, v0) = 10 * self.PX_PER_MM, self.ORIGIN
        for j in range(-1, 6):  # 10 x 7 squares around 9 x 6 inner corners
            for i in range(-1, 9):
                if (i + j) % 2 == 0:
                    x, y = int(u0 + i * s), int(v0 + j * s)
                    img[y : y + int(s), x : x + int(s)] = 0

        class Board:
            def capture(self):
                return img.copy()

            def close(self):
                pass

        devices.camera = Board()
        return devices


def on_bench(cls):
    """Run the test on this device factory instead of the plain FakeBench."""

    def mark(test):
        test.bench = cls
        return test

    return mark


@pytest.fixture(params=["in-process", "socket"])
def web(tmp_path, request):
    factory = getattr(request.function, "bench", FakeBench)("cone")
    mounts = tmp_path / "mounts"  # no stick plugged in until a test writes one here
    mounts.write_text("")
    usb = UsbExporter(
        mounts_file=mounts,
        roots=(str(tmp_path / "media"),),
        sys_root=tmp_path / "nosys",
        unmount=lambda s: mounts.write_text(""),
    )  # what the box's stick unit does
    svc = BenchService(
        tmp_path / "daemon", factory, processor=light_processor, panel_interval_s=0.05, usb=usb
    )
    server = client = None
    target = svc
    if request.param == "socket":
        # production layout: the web server is its own process with no device access, talking to
        # the daemon over its Unix socket (rpc.BenchClient has the facade's methods)
        sock = tmp_path / "daemon.sock"
        server = rpc.serve(svc, sock)
        client = rpc.BenchClient(sock)
        target = client
    app = create_app(target, {"data_dir": str(tmp_path / "web")})
    c = app.test_client()
    c.environ_base["HTTP_X_CSRF_TOKEN"] = login(c, app.config["FIRST_RUN_PASSWORD"])
    yield c, svc
    if client:
        client.close()
    if server:
        server.shutdown()
        server.server_close()
    svc.close()


def test_the_daemon_copies_a_jobs_file_to_the_usb_stick_the_web_asks_for(web, tmp_path):
    """The web has no device access: it asks the daemon (in-process or over its socket)."""
    c, svc = web
    job_id = c.post("/api/scan", json=SCAN).get_json()["job_id"]
    assert wait_state(c, {"done", "failed"}, timeout=60)["state"] == "done"
    assert c.get("/api/usb").get_json() == {"available": False, "sticks": []}
    r = c.post(f"/api/jobs/{job_id}/usb", json={})
    assert r.status_code == 409 and r.get_json() == {"error": "no USB stick is plugged in", "where": "usb"}
    stick = tmp_path / "media" / "pi" / "STICK"
    stick.mkdir(parents=True)
    (tmp_path / "mounts").write_text(f"/dev/sdb1 {stick} vfat rw,nosuid,nodev 0 0\n")
    u = c.get("/api/usb").get_json()
    assert u["available"] and u["sticks"][0]["id"] == "sdb1"
    r = c.post(f"/api/jobs/{job_id}/usb", json={"file": "report.md", "stick": "sdb1"})
    assert r.status_code == 200, r.get_json()
    res = r.get_json()
    assert (
        res["safe_to_remove"]
        and res["verified"]
        and res["unmounted"]
        and res["name"] == f"{job_id}-report.md"
    )
    assert c.get("/api/usb").get_json() == {"available": False, "sticks": []}  # unmounted after the copy
    assert (stick / "inkslice" / res["name"]).read_bytes() == svc.job_file(job_id, "report.md").read_bytes()
    assert c.post(f"/api/jobs/{job_id}/usb", json={"file": "../daemon.sock"}).status_code in (400, 404)


def test_a_scan_through_the_web_on_the_real_service(web):
    c, svc = web
    assert c.get("/api/state").get_json()["state"] == "idle"
    r = c.post("/api/scan", json={**SCAN, "level_step_mm": 0})
    assert r.status_code == 400 and r.get_json()["where"] == "level_step_mm"
    r = c.post("/api/scan", json=SCAN)
    assert r.status_code == 201, r.get_json()
    job_id = r.get_json()["job_id"]
    st = wait_state(c, {"done", "failed"}, timeout=60)
    assert st["state"] == "done", st
    # 10 levels of 2 mm, and the frames the runner's refinement adds where a face came out at once
    assert st["levels_done"] == st["levels_total"] >= 10
    info = c.get(f"/api/jobs/{job_id}").get_json()
    assert {"heightmap.csv", "toolpath.gcode", "report.json"} <= set(info["outputs"])
    for name in info["outputs"]:
        r = c.get(f"/api/jobs/{job_id}/files/{name}")
        assert r.status_code == 200 and r.data == svc.job_file(job_id, name).read_bytes(), name
    # the job page renders the daemon's report (nested statistics per method) and the 3D view
    page = c.get(f"/jobs/{job_id}").get_data(as_text=True)
    assert 'id="view3d"' in page and "Ea" in page
    # the zip has the outputs and the scan folder (scan.json + every frame it lists)
    z = zipfile.ZipFile(io.BytesIO(c.get(f"/api/jobs/{job_id}/archive.zip").data))
    names = set(z.namelist())
    doc = json.loads(z.read(f"{job_id}/scan/scan.json"))
    assert len(doc["frames"]) == st["levels_total"]
    assert {f"{job_id}/scan/{f['file']}" for f in doc["frames"]} <= names
    assert {f"{job_id}/{n}" for n in info["outputs"]} <= names
    r = c.get("/api/frame.jpg")
    assert r.status_code == 200 and r.data[:2] == b"\xff\xd8"
    # the daemon's own extras answer too (their tests are below)
    assert c.get("/api/heightmap/live").status_code == 200
    assert c.get("/api/calibration").get_json()["step"] == 0
    r = c.patch("/api/settings", json={"dialect": "heidenhain"})
    assert r.status_code == 400 and r.get_json()["where"] == "dialect"
    assert c.patch("/api/settings", json={"dialect": "grbl"}).get_json()["dialect"] == "grbl"
    assert c.get("/settings").status_code == 200
    # traversal through the web never reaches the daemon's other files
    for bad in ("..%2fdaemon.db", "scan%2fscan.json", "..", ".hidden"):
        assert c.get(f"/api/jobs/{job_id}/files/{bad}").status_code in (400, 404)


def test_the_live_height_map_grows_during_a_scan(web):
    c, svc = web
    assert c.get("/api/heightmap/live").status_code == 204  # no scan yet
    r = c.post("/api/scan", json={**SCAN, "settle_s": 0.15})
    assert r.status_code == 201
    counts = []
    while True:
        st = c.get("/api/state").get_json()
        r = c.get("/api/heightmap/live")
        if r.status_code == 200:
            hm = r.get_json()
            assert len(hm["x"]) == len(hm["y"]) == len(hm["z"]) == len(hm["z"][0])
            counts.append(sum(v is not None for row in hm["z"] for v in row))
        if st["state"] in ("done", "failed"):
            break
    assert st["state"] == "done", st
    hm = c.get("/api/heightmap/live").get_json()
    known = [v for row in hm["z"] for v in row if v is not None]
    # the cone emerges from the ink: the map fills in as the levels go down, never shrinks
    assert counts == sorted(counts) and counts[0] < counts[-1] == len(known)
    # the first level (24) is above the tip (23.2); the tip is a cell or two wide by 20
    assert max(known) in (22.0, 20.0) and min(known) == 6.0
    assert any(v is None for row in hm["z"] for v in row)  # the base around the cone


@on_bench(ChessboardBench)
def test_guided_calibration_on_the_daemon(web):
    c, svc = web
    cal = c.get("/api/calibration").get_json()
    assert [s["id"] for s in cal["steps"]] == ["home", "target", "detect", "accept"] and cal["step"] == 0
    r = c.post("/api/calibration/detect")
    assert r.status_code == 400 and "home" in r.get_json()["error"]
    assert c.post("/api/calibration/home").get_json()["step"] == 1
    # the bench is held by the calibration: no scan meanwhile
    r = c.post("/api/scan", json=SCAN)
    assert r.status_code == 400 and "calibration" in r.get_json()["error"]
    assert c.post("/api/calibration/target").get_json()["step"] == 2
    cal = c.post("/api/calibration/detect").get_json()
    d = cal["detected"]
    assert d["corners"] == 54 and d["plane_rms_mm"] < 0.05 and abs(d["mm_per_px"] - 0.25) < 0.002, d
    r = c.get("/api/frame.jpg")  # the preview with the corners drawn
    assert r.status_code == 200 and r.data[:2] == b"\xff\xd8"
    assert c.post("/api/calibration/accept").get_json() == {
        **cal,
        "step": 0,
        "detected": None,
        "holds_bench": False,
    }
    cam = svc.store.calibrations()[0]["camera"]
    import numpy as np

    H = np.asarray(cam["homography"])
    # OpenCV puts pixel centres at integers: the corner drawn at column 150 lies at u = 149.5;
    # the board lies at the jig, its first corner at (10, 75) mm on the base
    for (u, v), want in (
        ((149.5, 129.5), (10, 75)),
        ((149.5 + 40 * 8, 129.5), (90, 75)),
        ((149.5, 129.5 + 40 * 5), (10, 25)),
    ):
        p = H @ [u, v, 1]
        assert np.allclose(p[:2] / p[2], want, atol=0.1), (u, v, p[:2] / p[2])
    assert (cam["width"], cam["height"]) == (640, 480)
    # the bench is free again
    r = c.post("/api/scan", json=SCAN)
    assert r.status_code == 201, r.get_json()
    assert wait_state(c, {"done", "failed"}, timeout=60)["state"] == "done"


class SlowChessboardBench(ChessboardBench):
    """The board bench whose stage travels at 10 s per 100 mm: homing from mid-travel takes 4 s."""

    def __init__(self, surface):
        super().__init__(surface, faults={"stage": {"seconds_per_mm": 0.1}})


def scan_then_cancel(c):
    """The bench takes a scan (201), which is then cancelled so the next case starts idle."""
    r = c.post("/api/scan", json={**SCAN, "settle_s": 0.2})
    assert r.status_code == 201, r.get_json()
    assert c.post("/api/scan/cancel").status_code == 200
    assert wait_state(c, {"cancelled", "done", "failed"}, timeout=30)["state"] in ("cancelled", "done")


@on_bench(ChessboardBench)
def test_the_calibration_can_be_cancelled_at_every_step(web):
    c, svc = web
    steps = ["home", "target", "detect", "accept"]
    for n_done in range(len(steps)):
        for step in steps[:n_done]:
            assert c.post(f"/api/calibration/{step}").status_code == 200, step
        held = c.get("/api/calibration").get_json()
        assert held["step"] == n_done and held["holds_bench"] == (n_done > 0)
        if n_done:
            r = c.post("/api/scan", json=SCAN)
            assert r.status_code == 400 and "cancel" in r.get_json()["error"], r.get_json()
        cal = c.post("/api/calibration/cancel").get_json()
        assert cal["step"] == 0 and cal["holds_bench"] is False and cal["detected"] is None, (n_done, cal)
        assert svc.store.calibrations() == []  # nothing half-done was stored
        assert svc.factory.last is None or svc.factory.last.light.on is False
        scan_then_cancel(c)
    # after all that, the full sequence still works from "home"
    for step in steps:
        assert c.post(f"/api/calibration/{step}").status_code == 200, step
    assert len(svc.store.calibrations()) == 1


@on_bench(SlowChessboardBench)
def test_cancel_stops_a_step_that_is_still_running(web):
    import threading
    import time

    c, svc = web
    outcome = {}

    def home():
        try:
            outcome["home"] = svc.calibrate("home")
        except Exception as e:  # the interrupted homing ends with the stage's error
            outcome["home"] = e

    t = threading.Thread(target=home)
    t.start()
    wait_until(
        lambda: svc.factory.last and "home" in svc.factory.last.stage.calls, what="the homing", every=0.01
    )
    t0 = time.monotonic()
    cal = c.post("/api/calibration/cancel").get_json()
    took = time.monotonic() - t0
    t.join(5)
    assert cal["step"] == 0 and cal["holds_bench"] is False
    assert took < 2.0, f"cancel waited {took:.1f} s for a 4 s homing"
    assert "stop" in svc.factory.last.stage.calls and isinstance(outcome["home"], Exception)
    scan_then_cancel(c)


def scan_folder_zip(folder, prefix="myscan/", edit=None, extra=None):
    doc = json.loads((folder / "scan.json").read_text())
    if edit:
        doc = edit(doc)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr(prefix + "scan.json", json.dumps(doc))
        for fr in json.loads((folder / "scan.json").read_text())["frames"]:
            z.write(folder / fr["file"], prefix + fr["file"])
        for name, data in (extra or {}).items():
            z.writestr(prefix + name, data)
    return buf.getvalue()


def test_scan_folder_import_on_the_daemon(web, tmp_path):
    c, svc = web
    r = c.post("/api/scan", json=SCAN)
    first = r.get_json()["job_id"]
    assert wait_state(c, {"done", "failed"}, timeout=60)["state"] == "done"
    folder = svc.store.job_dir(first) / "scan"
    uploads = tmp_path / "web" / "web" / "uploads"
    jobs_dir = svc.store.jobs_dir

    def post(body):
        return c.post(
            "/api/uploads/scan",
            data={"file": (io.BytesIO(body), "scan.zip")},
            content_type="multipart/form-data",
        )

    def nothing_left(n_jobs):
        assert len(svc.jobs()) == n_jobs
        assert sorted(p.name for p in jobs_dir.iterdir()) == sorted(j["id"] for j in svc.jobs())
        assert not uploads.exists() or list(uploads.iterdir()) == []

    # refused by the scan format's checks (scanfile: the web makes them before unpacking, the
    # daemon again on the unpacked folder), after the web's zip checks passed
    import cv2
    import numpy as np

    ok, small_png = cv2.imencode(".png", np.zeros((10, 10, 3), np.uint8))
    bad = {
        "no camera": scan_folder_zip(folder, edit=lambda d: {k: v for k, v in d.items() if k != "camera"}),
        "singular homography": scan_folder_zip(
            folder, edit=lambda d: {**d, "camera": {**d["camera"], "homography": [[0] * 3] * 3}}
        ),
        "wrong frame size": scan_folder_zip(
            folder,
            edit=lambda d: {**d, "frames": d["frames"] + [{"file": "frames/small.png", "level_mm": 1.0}]},
            extra={"frames/small.png": small_png.tobytes()},
        ),
        "not an image": scan_folder_zip(
            folder,
            edit=lambda d: {**d, "frames": d["frames"] + [{"file": "frames/x.png", "level_mm": 1.0}]},
            extra={"frames/x.png": b"#!/bin/sh\nrm -rf /\n"},
        ),
        "units": scan_folder_zip(folder, edit=lambda d: {**d, "units": "inch"}),
    }
    for case, body in bad.items():
        r = post(body)
        assert r.status_code == 400, (case, r.status_code, r.get_json())
        assert r.get_json()["error"], case
        nothing_left(1)

    # a good one becomes a job, processed like a scan, its folder the daemon's own copy
    r = post(scan_folder_zip(folder))
    assert r.status_code == 201, r.get_json()
    job_id = r.get_json()["job_id"]
    assert wait_state(c, {"done", "failed"}, timeout=60)["state"] == "done"
    info = c.get(f"/api/jobs/{job_id}").get_json()
    frames = len(json.loads((folder / "scan.json").read_text())["frames"])
    assert info["status"] == "done" and info["params"]["imported"] and info["levels_done"] == frames >= 10
    assert "toolpath.gcode" in info["outputs"]
    copied = svc.store.job_dir(job_id) / "scan"
    assert sorted(p.name for p in (copied / "frames").iterdir()) == sorted(
        p.name for p in (folder / "frames").iterdir()
    )
    assert json.loads((copied / "scan.json").read_text()) == json.loads((folder / "scan.json").read_text())
    nothing_left(2)

    # the box's own archive of a job (outputs, job.json and JOB/scan/...) imports as it is
    archive = c.get(f"/api/jobs/{first}/archive.zip").data
    r = post(archive)
    assert r.status_code == 201, r.get_json()
    assert wait_state(c, {"done", "failed"}, timeout=60)["state"] == "done"
    again = svc.store.job_dir(r.get_json()["job_id"])
    assert (again / "scan" / "scan.json").is_file() and not (again / "job.json").exists()
    nothing_left(3)


def test_the_bench_buttons_news_reach_the_dashboard(web):
    c, svc = web
    assert c.get("/api/state").get_json()["notice"] is None
    svc.export_latest_gcode()  # what the long press runs (no job finished yet)
    import time

    time.sleep(0.2)  # the web caches the state for 0.1 s
    n = c.get("/api/state").get_json()["notice"]
    assert (
        n["code"] == "no_gcode"
        and n["text"] == "USB export: no finished job with G-code to copy"
        and not n["ok"]
    )
    assert 0 <= n["age_s"] < 5 and "lines" not in n
    assert 'id="notice"' in c.get("/").get_data(as_text=True)
