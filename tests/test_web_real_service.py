"""The web UI on the daemon team's real BenchService (fake devices), in-process and over its socket."""
import io
import json
import zipfile
from pathlib import Path

import pytest

from appliance.daemon import rpc
from appliance.daemon.service import BenchService
from appliance.sim.fakes import FakeBench
from appliance.web import create_app
from web_helpers import NoUsb, login, wait_state

SCAN = {"name": "cone", "surface": "cone", "levels_to_mm": 20.0, "levels_from_mm": 2.0,
        "level_step_mm": 2.0, "settle_s": 0.0}


def light_processor(scan_folder, out_folder, options, stop=None):
    """Stands in for process_scan: the web's concern is the facade, not the science (the daemon's
    tests run the real pipeline), and the pipeline's cost must not set this test's pace.
    It writes what process_scan writes, shaped the same way, from the real scan folder."""
    from appliance.atomicio import write_bytes, write_json, write_text
    frames = json.loads((Path(scan_folder) / "scan.json").read_text())["frames"]
    out = Path(out_folder)
    rows = ["x,y,z"] + [f"{x}.0000,{y}.0000,{min(x, y, 4 - x, 4 - y) * 1.5:.4f}" for x in range(5) for y in range(5)]
    write_text(out / "heightmap.csv", "\n".join(rows) + "\n")
    write_text(out / "toolpath.gcode", "G21 G90\nF800\n" + "".join(f"G1 X{x} Y0 Z1\n" for x in range(5)) + "M2\n")
    write_json(out / "report.json", {"statistics": {"inkslice:fit": {"n": len(frames), "Ea": 0.0722, "sigma": 0.144}}})
    write_text(out / "report.md", "# report\n")
    write_bytes(out / "error_inkslice_fit.png", Path(scan_folder, frames[0]["file"]).read_bytes())
    return {"outputs": ["error_inkslice_fit.png", "heightmap.csv", "report.json", "report.md", "toolpath.gcode"]}


@pytest.fixture(params=["in-process", "socket"])
def web(tmp_path, request):
    svc = BenchService(tmp_path / "daemon", FakeBench("cone"), processor=light_processor, panel_interval_s=0.05)
    server = client = None
    target = svc
    if request.param == "socket":
        # production layout: the web server is its own process with no device access, talking to
        # the daemon over its Unix socket (rpc.BenchClient has the facade's methods)
        sock = tmp_path / "daemon.sock"
        server = rpc.serve(svc, sock)
        client = rpc.BenchClient(sock)
        target = client
    app = create_app(target, {"data_dir": str(tmp_path / "web"), "usb": NoUsb()})
    c = app.test_client()
    c.environ_base["HTTP_X_CSRF_TOKEN"] = login(c, app.config["FIRST_RUN_PASSWORD"])
    yield c, svc
    if client:
        client.close()
    if server:
        server.shutdown()
        server.server_close()
    svc.close()


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
    assert st["levels_done"] == st["levels_total"] == 10
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
    assert len(doc["frames"]) == 10
    assert {f"{job_id}/scan/{f['file']}" for f in doc["frames"]} <= names
    assert {f"{job_id}/{n}" for n in info["outputs"]} <= names
    r = c.get("/api/frame.jpg")
    assert r.status_code == 200 and r.data[:2] == b"\xff\xd8"
    # live features the daemon does not offer are reported as such, not as crashes
    assert c.get("/api/heightmap/live").status_code == 501
    assert c.get("/api/calibration").status_code == 501
    r = c.patch("/api/settings", json={"dialect": "heidenhain"})
    assert r.status_code == 400 and r.get_json()["where"] == "dialect"
    assert c.patch("/api/settings", json={"dialect": "grbl"}).get_json()["dialect"] == "grbl"
    assert c.get("/settings").status_code == 200
    # traversal through the web never reaches the daemon's other files
    for bad in ("..%2fdaemon.db", "scan%2fscan.json", "..", ".hidden"):
        assert c.get(f"/api/jobs/{job_id}/files/{bad}").status_code in (400, 404)
