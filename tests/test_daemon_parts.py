"""The daemon's smaller parts: the level plan, the store, the socket facade,
sd_notify and the watchdog, the drivers' failure modes without hardware."""

import json
import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from daemon_helpers import SCAN, service, wait_final

from appliance.daemon import settings as S
from appliance.daemon.levels import LevelPlan, waterline_change
from appliance.daemon.notify import notify, watchdog_interval
from appliance.daemon.store import Store
from appliance.errors import DeviceError, InkSliceError, SettingError
from appliance.scanfile import FrameRef


def frames_of(plan):
    frames = []
    while (nxt := plan.next_target(frames)) is not None:
        frames.append(FrameRef("f", nxt[0], {"target_mm": nxt[0], "step_mm": nxt[1], "change": 0.05}))
    return [f.level_mm for f in frames]


def test_a_fixed_plan_runs_top_down_and_ends_on_the_bottom():
    plan = LevelPlan(
        S.validate(S.DEFAULTS, {"levels_to_mm": 10.0, "levels_from_mm": 1.0, "level_step_mm": 2.0})
    )
    assert frames_of(plan) == [10.0, 8.0, 6.0, 4.0, 2.0, 1.0]
    assert plan.estimate_total([]) == 6
    plan = LevelPlan(
        S.validate(S.DEFAULTS, {"levels_to_mm": 10.0, "levels_from_mm": 0.0, "level_step_mm": 0.1})
    )
    levels = frames_of(plan)
    assert len(levels) == 101 == plan.estimate_total([]) and levels[-1] == 0.0
    assert max(abs(a - (10.0 - 0.1 * k)) for k, a in enumerate(levels)) < 1e-9  # computed, no drift


def test_the_adaptive_rule_aims_at_the_target_change_within_bounds():
    plan = LevelPlan(
        S.validate(
            S.DEFAULTS,
            {"step_mode": "adaptive", "step_min_mm": 0.2, "step_max_mm": 3.0, "adaptive_change": 0.02},
        )
    )
    assert plan.next_step(1.0, 0.04) == pytest.approx(0.5)  # twice the target: half the step
    assert plan.next_step(1.0, 0.01) == pytest.approx(2.0)  # half: double (at most 2x per frame)
    assert plan.next_step(1.0, 1.0) == pytest.approx(0.2)  # bounded below
    assert plan.next_step(2.0, 0.0) == pytest.approx(3.0)  # nothing visible: bounded above
    a = np.zeros((10, 10), bool)
    b = a.copy()
    b[2:6, 2:6] = True
    c = b.copy()
    c[2:6, 6] = True
    assert waterline_change(None, b) == 0.0 and waterline_change(a, a) == 0.0
    assert waterline_change(b, c) == pytest.approx(4 / 20)


def test_settings_validation_names_the_key():
    with pytest.raises(SettingError) as e:
        S.validate(S.DEFAULTS, {"step_min_mm": 3.0, "step_max_mm": 2.0})
    assert e.value.where == "step_min_mm"
    with pytest.raises(SettingError) as e:
        S.validate(S.DEFAULTS, {"level_step_mm": 1e-4})
    assert e.value.where == "level_step_mm" and "more than" in e.value.problem
    with pytest.raises(SettingError) as e:
        S.validate(S.DEFAULTS, {"levels_to_mm": 70.0, "envelope_z_mm": 100.0})
    assert "home" in e.value.problem


def test_the_store_keeps_jobs_settings_calibrations_and_events(tmp_path):
    store = Store(tmp_path)
    store.create_job("j1", "first", {"a": 1}, {"surface": "cone"}, 5)
    store.update_job("j1", status="scanning", levels_done=2, outputs=["x.csv"])
    store.save_settings({"level_step_mm": 0.3})
    store.add_calibration({"camera": {"width": 1}})
    store.close()
    store = Store(tmp_path)  # everything survives a reopen
    job = store.get_job("j1")
    assert (job["status"], job["levels_done"], job["outputs"], job["params"]) == (
        "scanning",
        2,
        ["x.csv"],
        {"surface": "cone"},
    )
    assert store.load_settings() == {"level_step_mm": 0.3}
    assert store.calibrations()[0]["camera"] == {"width": 1}
    assert store.events("j1")[0]["kind"] == "created"
    assert store.integrity_ok()
    assert store._db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    with pytest.raises(InkSliceError, match="no such job"):
        store.get_job("j2")
    store.close()


def test_the_socket_client_is_the_facade(tmp_path):
    from appliance.daemon.rpc import BenchClient, serve

    svc, _ = service(tmp_path)
    server = serve(svc, tmp_path / "d.sock")
    client = BenchClient(tmp_path / "d.sock")
    try:
        assert client.state()["state"] == "idle"
        with pytest.raises(SettingError) as e:  # the error type and its parts survive the trip
            client.start_scan({**SCAN, "level_step_mm": -1})
        assert e.value.where == "level_step_mm"
        # subscribe before starting: on a busy machine homing can be over before a
        # subscription made after start_scan sees its first state
        stream = client.subscribe(timeout=60)  # streamed over the socket as they change
        assert next(stream)["state"] == "idle"
        job_id = client.start_scan(SCAN)
        states = []
        for st in stream:
            states.append(st["state"])
            if st["state"] == "done":
                break
        assert {"homing", "scanning", "processing", "done"} <= set(states)
        assert client.job(job_id)["status"] == "done"
        assert client.jobs()[0]["id"] == job_id
        assert client.job_file(job_id, "heightmap.csv").read_text().startswith("x,y,z")
        with pytest.raises(InkSliceError):
            client.job_file(job_id, "../../inkslice.db")
        jpeg, info = client.latest_frame()
        assert jpeg[:2] == b"\xff\xd8" and info["level_mm"] == 6.0
        assert client.update_settings({"settle_s": 0.2})["settle_s"] == 0.2
        assert client.settings()["settle_s"] == 0.2
        assert any(e["kind"] == "done" for e in client.events(job_id))
    finally:
        server.shutdown()
        server.server_close()
        svc.close()
    with pytest.raises(DeviceError, match="not reachable"):
        BenchClient(tmp_path / "nothing.sock").state()


def test_subscribe_ends_at_its_timeout(tmp_path):
    svc, _ = service(tmp_path)
    try:
        t0 = time.monotonic()
        got = list(svc.subscribe(timeout=0.3))
        assert got[0]["state"] == "idle" and 0.25 < time.monotonic() - t0 < 2.0
    finally:
        svc.close()


def test_the_level_sensor_reading_is_kept_with_each_frame(tmp_path):
    from appliance.daemon.processing import in_process
    from appliance.daemon.service import BenchService
    from appliance.sim.fakes import FakeBench

    svc = BenchService(tmp_path / "data", FakeBench("cone", level_sensor=True), processor=in_process)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        frames = json.loads(svc.job_file(job["id"], "scan/scan.json").read_text())["frames"]
        # by level, from the top (a refined step's frames were taken going back up into it)
        drops = [f["sensor_minus_nominal_mm"] for f in sorted(frames, key=lambda f: -f["level_mm"])]
        assert len(drops) > 10
        # the tip only: hardly any displacement; the more of the cone stands above the ink, the lower it is
        assert -0.02 < drops[0] <= 0.0 and drops[-1] < -0.1 and all(a >= b for a, b in zip(drops, drops[1:]))
    finally:
        svc.close()


def test_notify_sends_datagrams_and_the_daemon_pings_the_watchdog(tmp_path, monkeypatch):
    path = str(tmp_path / "notify.sock")
    rx = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    rx.bind(path)
    rx.settimeout(20)
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    assert notify("READY=1") is False  # outside systemd: a no-op
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    assert notify("STATUS=x") is True and rx.recv(100) == b"STATUS=x"
    monkeypatch.setenv("WATCHDOG_USEC", "400000")
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid()))
    assert watchdog_interval() == pytest.approx(0.2)
    env = {**os.environ, "NOTIFY_SOCKET": path, "WATCHDOG_USEC": "300000"}
    env.pop("WATCHDOG_PID")
    proc = subprocess.Popen(
        [sys.executable, "-m", "appliance.cli", "daemon", "--sim", "fake", "--data", str(tmp_path / "data")],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        got = []
        while not (any(m.startswith(b"READY=1") for m in got) and got.count(b"WATCHDOG=1") >= 3):
            got.append(rx.recv(1000))
    finally:
        proc.terminate()
        assert proc.wait(timeout=20) == 0
        rx.close()
    assert got.index(b"WATCHDOG=1") > [i for i, m in enumerate(got) if m.startswith(b"READY=1")][0]


def test_drivers_report_missing_hardware_clearly(tmp_path):
    from appliance.hw.camera import V4L2Camera, find_by_id
    from appliance.hw.devices import HardwareBench

    with pytest.raises(DeviceError, match="no such device"):
        V4L2Camera(str(tmp_path / "video9"))
    with pytest.raises(DeviceError, match="plugged"):
        find_by_id("no-such-camera-xyz")
    bench = HardwareBench(
        {"gpiochip": str(tmp_path / "gpiochip9"), "i2c_bus": 97, "stage_port": str(tmp_path / "ttyACM9")}
    )
    panel = bench.open_panel()  # all missing: reported, not raised
    assert set(panel.hardware) == {"led", "button", "display"}
    assert all(v.startswith("missing") for v in panel.hardware.values()), panel.hardware
    assert panel.led is None and panel.display is None
    with pytest.raises(DeviceError, match="serial port"):
        bench.open(S.DEFAULTS, {})  # the stage is required


def test_the_daemon_runs_on_without_a_panel(tmp_path):
    from appliance.daemon.processing import in_process
    from appliance.daemon.service import BenchService
    from appliance.hw.devices import HardwareBench
    from appliance.sim.fakes import FakeBench

    class NoPanel(FakeBench):
        open_panel = HardwareBench({"gpiochip": str(tmp_path / "none"), "i2c_bus": 97}).open_panel

    svc = BenchService(tmp_path / "data", NoPanel("cone"), processor=in_process)
    try:
        assert svc.state()["hardware"]["display"].startswith("missing")
        assert wait_final(svc, svc.start_scan(SCAN))["status"] == "done"
    finally:
        svc.close()


def test_the_display_picture_is_in_ssd1306_page_order():
    from appliance.hw.display import HEIGHT, WIDTH, render_lines, to_pages

    img = np.zeros((HEIGHT, WIDTH), np.uint8)
    img[0, 0] = 1  # page 0, column 0, bit 0
    img[9, 5] = 1  # page 1, column 5, bit 1
    img[63, 127] = 1  # page 7, column 127, bit 7
    pages = to_pages(img)
    assert len(pages) == 1024
    assert pages[0] == 1 and pages[128 + 5] == 2 and pages[7 * 128 + 127] == 128 and sum(pages) == 131
    lit = render_lines(["SCANNING", "level 12.40 mm", "12/80", "192.168.1.20"])
    assert lit.max() == 1 and lit[:16].sum() > 20 and lit[48:].sum() > 20


def test_auto_resume_continues_an_interrupted_scan_at_start(tmp_path):
    from appliance.daemon.processing import in_process
    from appliance.daemon.service import BenchService
    from appliance.sim.fakes import FakeBench

    store = Store(tmp_path / "data")  # what a killed daemon leaves behind
    settings = S.validate(S.DEFAULTS, {k: v for k, v in SCAN.items() if k in S.DEFAULTS})
    store.create_job("j1", "cone", settings, {"name": "cone", "surface": "cone"}, 10)
    store.update_job("j1", status="scanning")
    store.save_settings({"auto_resume": True})
    store.close()
    svc = BenchService(tmp_path / "data", FakeBench("cone"), processor=in_process)
    try:
        assert svc.interrupted == ["j1"]
        job = wait_final(svc, "j1")
        assert job["status"] == "done" and job["attempts"] == 2
        assert job["levels_done"] == job["levels_total"] > 10  # the plan's 10 and the refinement's
        assert [e["kind"] for e in svc.events("j1")][:3] == ["done", "resumed", "interrupted"]
    finally:
        svc.close()


def test_the_settle_time_waits_out_the_virtual_inks_ripple(tmp_path):
    """With ripple on, a frame taken at once sees a ringing surface; after the
    settle time (several decay times) it equals the still frame."""
    import time

    from appliance.sim.fakes import LevelSeededCamera, small_rig
    from appliance.sim.render import Effects

    rig = small_rig(320, 240)
    still = LevelSeededCamera("cone", rig, lambda: 10.0).capture()
    rippling = LevelSeededCamera(
        "cone", rig, lambda: 10.0, effects=Effects(ripple_mm=0.3, ripple_decay_s=0.1), clock=time.monotonic
    )
    rippling.note_move_finished()
    at_once = rippling.capture()
    time.sleep(2.0)  # 20 decay times: the daemon's settle_s
    settled = rippling.capture()
    assert np.abs(at_once.astype(int) - still).max() > 20
    assert np.abs(settled.astype(int) - still).max() <= 1


def test_processing_options_are_what_process_scan_takes():
    import inspect

    from appliance import process as P
    from appliance.daemon.processing import options_for

    accepted = set(inspect.signature(P.process).parameters) | set(
        inspect.signature(P.process_scan).parameters
    )
    opts = options_for(S.DEFAULTS)
    assert set(opts) <= accepted and opts["grid_n"] == 50 and "method" not in opts  # "" = its default
    methods = [m for m in S.surface_methods() if m]
    opts = options_for(S.validate(S.DEFAULTS, {"method": methods[-1], "cutter_diameter_mm": 3.0}))
    assert opts["method"] == methods[-1] and opts["keep"] == ["scan"]
    assert opts["cam_options"]["cutter"] == "ball3" and opts["cam_options"]["dialect"] == "linuxcnc"
    with pytest.raises(SettingError) as e:
        S.validate(S.DEFAULTS, {"method": "bicubic-magic"})
    assert e.value.where == "method"
