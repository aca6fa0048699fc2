"""Shared bits for the web tests: an app on the daemon's real BenchService driving the in-memory
bench (sim.fakes.FakeBench, a cone), logged-in clients.

The bench's stored settings make a scan short (QUICK: ten levels from 24 mm down to 6 mm, no
settle time) and light_processor stands in for the pipeline, so a whole scan takes a few
seconds; the daemon's own tests run the real pipeline."""

import json
import re
from pathlib import Path

from polling import wait_until

from appliance.daemon.service import BenchService
from appliance.sim.fakes import FakeBench
from appliance.web import create_app

CSRF_RE = re.compile(r'name="csrf-token" content="([^"]+)"')
QUICK = {"levels_to_mm": 24.0, "levels_from_mm": 6.0, "level_step_mm": 2.0, "settle_s": 0.0}


def light_processor(scan_folder, out_folder, options, stop=None, size=5):
    """Stands in for process_scan: the web's concern is the facade, not the science (the daemon's
    tests run the real pipeline), and the pipeline's cost must not set this test's pace.
    It writes what process_scan writes, shaped the same way, from the real scan folder; the
    height map is a pyramid on a `size` x `size` grid of 1 mm cells."""
    from appliance.atomicio import write_bytes, write_json, write_text

    frames = json.loads((Path(scan_folder) / "scan.json").read_text())["frames"]
    out = Path(out_folder)
    top = size - 1
    rows = ["x,y,z"] + [
        f"{x}.0000,{y}.0000,{min(x, y, top - x, top - y) * 1.5:.4f}" for x in range(size) for y in range(size)
    ]
    write_text(out / "heightmap.csv", "\n".join(rows) + "\n")
    write_text(
        out / "toolpath.gcode", "G21 G90\nF800\n" + "".join(f"G1 X{x} Y0 Z1\n" for x in range(5)) + "M2\n"
    )
    write_json(
        out / "report.json",
        {
            "statistics": {"inkslice:fit": {"n": len(frames), "Ea": 0.0722, "sigma": 0.144}},
            "notes": [NOTE],
        },
    )
    write_text(out / "report.md", "# report\n")
    write_bytes(out / "error_inkslice_fit.png", Path(scan_folder, frames[0]["file"]).read_bytes())
    return {
        "outputs": ["error_inkslice_fit.png", "heightmap.csv", "report.json", "report.md", "toolpath.gcode"]
    }


NOTE = "InkSlice regularised fit: a pocket held ink (around x 50.0, y 50.0 mm, 1095 mm²): its floor was never seen"


def part_processor(scan_folder, out_folder, options, stop=None):
    """light_processor with a height map a cutter fits on (a 21 mm pyramid), for re-posting."""
    return light_processor(scan_folder, out_folder, options, stop, size=21)


def bench_service(folder, settle_s=0.0, usb=None, factory=None, processor=light_processor):
    """The real BenchService on the in-memory bench, its scans QUICK (`settle_s` per level)."""
    svc = BenchService(
        Path(folder), factory or FakeBench("cone"), processor=processor, panel_interval_s=0.05, usb=usb
    )
    svc.update_settings({**QUICK, "settle_s": settle_s})
    return svc


def make_app(tmp_path, fast=True, factory=None, **config):
    """(app, service); not `fast`: each level settles 0.2 s, so a scan lasts a few seconds.
    `factory`: another device factory than the plain FakeBench (e.g. with a board in view)."""
    svc = bench_service(tmp_path / "bench", settle_s=0.0 if fast else 0.2, factory=factory)
    cfg = {"data_dir": str(tmp_path / "data")}
    cfg.update(config)
    app = create_app(svc, cfg)
    app.config["TESTING"] = True
    return app, svc


def csrf_of(client, path="/login"):
    return CSRF_RE.search(client.get(path).get_data(as_text=True)).group(1)


def login(client, password, addr="127.0.0.1"):
    tok = csrf_of(client)
    r = client.post(
        "/login", data={"password": password, "csrf_token": tok}, environ_base={"REMOTE_ADDR": addr}
    )
    assert r.status_code == 302, r.get_data(as_text=True)
    return csrf_of(client, "/")


def wait_state(client, states, timeout=20.0, headers=None):
    """/api/state once the bench is in one of `states`."""

    def state():
        st = client.get("/api/state", headers=headers or {}).get_json()
        return st if st["state"] in states else None

    return wait_until(state, timeout, what=f"the bench in {states}")


def wait_job(svc, job_id, timeout=20.0):
    """The job's record once it has ended (done, failed or cancelled)."""

    def ended():
        job = svc.job(job_id)
        return job if job["status"] in ("done", "failed", "cancelled") else None

    return wait_until(ended, timeout, what=lambda: f"job {job_id} to end: {svc.job(job_id)}")
