"""BenchService on the in-memory fake bench: the state machine, the facade,
cancel and resume, and faults leaving the hardware safe with a clear reason."""

import json
import time

import cv2
import numpy as np
import pytest
from daemon_helpers import SCAN, read_heightmap, service, wait_final

from appliance.cli import main as cli_main
from appliance.daemon.recovery import audit
from appliance.errors import InkSliceError, SettingError
from appliance.process import process_scan


def test_a_whole_scan_ends_done_and_matches_inkslice_process(tmp_path):
    svc, bench = service(tmp_path)
    seen = []
    try:
        job_id = svc.start_scan(SCAN)
        for st in svc.subscribe(timeout=60):
            seen.append(st["state"])
            if st["state"] == "done":
                break
        job = wait_final(svc, job_id)
        assert job["status"] == "done", job["reason"]
        # the plan's 10 levels, plus the frames that bisect the step in which the cone's top
        # came out at once (vision/refine.py; test_a_scan_cut_while_refining_... covers them)
        assert job["levels_done"] == job["levels_total"] > 10
        assert {"heightmap.csv", "toolpath.gcode", "report.md"} <= set(job["outputs"])
        # the states in order, as the UI sees them
        order = [s for i, s in enumerate(seen) if i == 0 or seen[i - 1] != s]
        assert order[-4:] == ["homing", "scanning", "processing", "done"]
        # the scan folder: levels from the top down, every frame listed and on disk
        scan_dir = svc.store.job_dir(job_id) / "scan"
        doc = json.loads((scan_dir / "scan.json").read_text())
        planned = [f["level_mm"] for f in doc["frames"] if "refines" not in f]
        assert planned == [24.0 - 2 * k for k in range(10)]
        assert len(doc["frames"]) == job["levels_total"]
        assert audit(svc.store) == []
        # the same folder through `inkslice process` (its defaults = the daemon's) gives the same files
        ref = tmp_path / "ref"
        assert cli_main(["process", str(scan_dir), "-o", str(ref), "--pipeline", "seed"]) == 0
        for name in ("heightmap.csv", "toolpath.gcode"):
            assert (ref / name).read_bytes() == svc.job_file(job_id, name).read_bytes(), name
        # the light was on only while capturing, and is off now
        light = bench.last.light
        assert light.on is False and light.history.count(True) == job["levels_total"]
        assert "stop" not in bench.last.stage.calls
    finally:
        svc.close()


def test_the_facade_refuses_what_it_must(tmp_path):
    svc, _ = service(tmp_path, faults={"stage": {"seconds_per_mm": 0.05}})
    try:
        with pytest.raises(SettingError) as e:
            svc.start_scan({**SCAN, "level_step_mm": 0})
        assert e.value.where == "level_step_mm"
        with pytest.raises(SettingError) as e:
            svc.start_scan({**SCAN, "levle_step_mm": 1})
        assert e.value.where == "levle_step_mm"
        with pytest.raises(SettingError) as e:
            svc.start_scan({**SCAN, "surface": "teapot"})
        assert "teapot" in str(e.value)
        with pytest.raises(SettingError) as e:
            svc.start_scan({**SCAN, "levels_to_mm": 1.0})
        assert e.value.where == "levels_to_mm"
        job_id = svc.start_scan(SCAN)
        with pytest.raises(SettingError, match="already running"):
            svc.start_scan(SCAN)
        with pytest.raises(SettingError, match="already running"):
            svc.resume(job_id)
        svc.cancel()
        svc.update_settings({"settle_s": 0.0})
        done = svc.start_scan({**SCAN, "levels_to_mm": 8.0})
        assert wait_final(svc, done)["status"] == "done"
        with pytest.raises(SettingError, match="only a failed"):
            svc.resume(done)
        for bad in ("../../inkslice.db", "/etc/passwd", "scan/../../" + job_id + "/x", "nonexistent.csv"):
            with pytest.raises(InkSliceError):
                svc.job_file(job_id, bad)
        assert svc.job_file(done, "scan/scan.json").name == "scan.json"
        with pytest.raises(InkSliceError, match="no such job"):
            svc.job("nope")
    finally:
        svc.close()


def test_settings_are_validated_and_stored(tmp_path):
    svc, _ = service(tmp_path)
    try:
        assert svc.update_settings({"level_step_mm": 0.25})["level_step_mm"] == 0.25
        for bad, key in (
            ({"level_step_mm": -1}, "level_step_mm"),
            ({"dialect": "heidenhain"}, "dialect"),
            ({"nope": 1}, "nope"),
            ({"grid": 2.5}, "grid"),
            ({"auto_resume": "yes"}, "auto_resume"),
        ):
            with pytest.raises(SettingError) as e:
                svc.update_settings(bad)
            assert e.value.where == key
        assert svc.settings()["level_step_mm"] == 0.25  # a refused change changed nothing
    finally:
        svc.close()
    svc2, _ = service(tmp_path)
    try:
        assert svc2.settings()["level_step_mm"] == 0.25  # survives a restart
    finally:
        svc2.close()


def test_latest_frame_is_a_small_jpeg_with_the_waterline(tmp_path):
    svc, _ = service(tmp_path)
    try:
        assert svc.latest_frame() is None
        wait_final(svc, svc.start_scan({**SCAN, "preview_width": 160}))
        jpeg, info = svc.latest_frame()
        img = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape[1] == 160 and info["level_mm"] == 6.0 and info["waterline"]
        red = img[..., 2].astype(int) - img[..., 1] > 60  # the drawn waterline
        assert red.sum() > 50
    finally:
        svc.close()


@pytest.mark.slow
def test_cancel_stops_the_motor_and_resume_matches_an_uninterrupted_scan(tmp_path):
    ref_svc, _ = service(tmp_path / "ref")
    try:
        ref = wait_final(ref_svc, ref_svc.start_scan(SCAN))
        ref_map = read_heightmap(ref_svc.job_file(ref["id"], "heightmap.csv"))
    finally:
        ref_svc.close()
    svc, bench = service(tmp_path, faults={"stage": {"seconds_per_mm": 0.05}})
    try:
        job_id = svc.start_scan(SCAN)
        for st in svc.subscribe(timeout=30):
            if st["levels_done"] >= 4:
                break
        svc.cancel()
        job = svc.job(job_id)
        assert job["status"] == "cancelled" and "frames so far are kept" in job["reason"]
        assert 4 <= job["levels_done"] < 10 and job["outputs"] == []
        assert bench.last.stage.calls[-1] == "stop" and bench.last.light.on is False
        svc.resume(job_id)
        job = wait_final(svc, job_id)
        assert job["status"] == "done" and job["attempts"] == 2
        assert bench.last.stage.calls[0] == "home"  # a resume re-homes first
        got = read_heightmap(svc.job_file(job_id, "heightmap.csv"))
        assert np.nanmax(np.abs(got - ref_map)) <= 0.005
        assert audit(svc.store) == []
    finally:
        svc.close()


@pytest.mark.parametrize(
    "faults, where, text",
    [
        ({"camera": {"unplug_after": 4}}, "camera", "unplugged"),
        ({"stage": {"reset_after_moves": 5}}, "stage", "controller was reset"),
        ({"stage": {"unplug_after_moves": 3}}, "stage", "unplugged"),
    ],
)
def test_device_faults_end_the_job_safely_with_a_clear_reason(tmp_path, faults, where, text):
    svc, bench = service(tmp_path, faults=faults)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "failed"
        assert job["reason"].startswith(where) and text in job["reason"], job["reason"]
        assert bench.last.light.on is False
        if "unplug_after_moves" not in faults.get("stage", {}):
            assert bench.last.stage.calls[-1] == "stop"  # motor stopped
        assert svc.state()["hardware"][where].startswith("fault")
        # what was captured is kept, and listed
        assert 2 <= job["levels_done"] <= 5
        assert audit(svc.store) == []
        # and the job resumes once the fault is gone
        bench.faults = {}
        svc.resume(job["id"])
        assert wait_final(svc, job["id"])["status"] == "done"
    finally:
        svc.close()


def test_a_nearly_full_disk_stops_the_scan_and_keeps_the_frames(tmp_path):
    calls = []

    def disk_free_mb(path):
        calls.append(path)
        return 5000.0 if len(calls) <= 3 else 150.0

    svc, bench = service(tmp_path, disk_free_mb=disk_free_mb)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "failed" and job["reason"].startswith("disk: nearly full: 150 MB free")
        assert job["levels_done"] == 3 and bench.last.light.on is False
        assert bench.last.stage.calls[-1] == "stop"
        assert audit(svc.store) == []
    finally:
        svc.close()


def test_a_real_enospc_while_writing_fails_the_job_without_a_half_frame(tmp_path, monkeypatch):
    import errno

    from appliance import atomicio

    real = atomicio.write_bytes
    count = {"n": 0}

    def failing(path, data):
        if str(path).endswith(".png"):
            count["n"] += 1
            if count["n"] == 4:
                raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, data)

    monkeypatch.setattr(atomicio, "write_bytes", failing)
    svc, bench = service(tmp_path)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "failed" and job["reason"].startswith("disk: full"), job["reason"]
        assert job["levels_done"] == 3
        assert audit(svc.store) == []
    finally:
        svc.close()


def test_a_processing_error_fails_the_job_and_keeps_the_scan(tmp_path):
    def broken(scan, out, options, stop):
        raise InkSliceError(scan, "no waterline found in any frame")

    svc, _ = service(tmp_path, processor=broken)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "failed" and "no waterline" in job["reason"]
        assert job["levels_done"] == job["levels_total"] > 10  # every frame kept
    finally:
        svc.close()


def test_processing_in_a_child_process_gives_the_same_files(tmp_path):
    from appliance.daemon.processing import child_process

    svc, _ = service(tmp_path, processor=child_process)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "done", job["reason"]
        ref = tmp_path / "ref"
        process_scan(svc.store.job_dir(job["id"]) / "scan", ref, pipeline="seed")
        assert (ref / "heightmap.csv").read_bytes() == svc.job_file(job["id"], "heightmap.csv").read_bytes()
        # the job log says where the child's time and memory went, phase by phase
        (logged,) = [e["message"] for e in svc.store.events(job["id"]) if e["kind"] == "processed"]
        assert logged.startswith("processing peak memory ")
        assert " s CPU; the seed method " in logged and " MB), writing outputs " in logged
    finally:
        svc.close()


def test_adaptive_steps_are_finer_where_the_waterline_moves_fast(tmp_path):
    svc, _ = service(tmp_path)
    try:
        params = {
            **SCAN,
            "step_mode": "adaptive",
            "level_step_mm": 1.0,
            "step_min_mm": 0.25,
            "step_max_mm": 4.0,
            "adaptive_change": 0.08,
            "levels_from_mm": 0.0,
        }
        job = wait_final(svc, svc.start_scan(params))
        assert job["status"] == "done", job["reason"]
        doc = json.loads(svc.job_file(job["id"], "scan/scan.json").read_text())
        # the plan's levels (a refined step's extra frames go back up into it)
        levels = np.array([f["level_mm"] for f in doc["frames"] if "refines" not in f])
        steps = -np.diff(levels)
        assert np.all(steps > 0) and levels[-1] == 0.0
        # near the apex the cone's section grows fastest relative to its size: the steps there
        # are the finest; lower down they grow towards step_max
        near_top = steps[levels[1:] > 15]
        low = steps[(levels[1:] < 12) & (levels[1:] > 4)]
        assert near_top.min() < low.max()
        assert steps.max() <= 4.0 + 1e-9 and steps[:-1].min() >= 0.25 - 1e-9
    finally:
        svc.close()


def test_panel_reports_missing_hardware_and_the_button_starts_and_cancels(tmp_path):
    svc, bench = service(
        tmp_path, faults={"panel": {"display": "missing"}, "stage": {"seconds_per_mm": 0.05}}
    )
    try:
        hw = svc.state()["hardware"]
        assert hw["display"] == "missing" and hw["led"] == "ok"
        svc.update_settings({"levels_to_mm": 10.0, "level_step_mm": 1.0, "settle_s": 0.0})
        bench.panel.button.press()
        for st in svc.subscribe(timeout=10):
            if st["state"] == "scanning":
                break
        assert svc.jobs()[0]["name"] == "started at the bench"
        import time

        time.sleep(0.1)
        assert bench.panel.led.on is True  # steady on while working
        bench.panel.button.press()
        for st in svc.subscribe(timeout=10):
            if st["state"] == "cancelled":
                break
        assert svc.jobs()[0]["status"] == "cancelled"
    finally:
        svc.close()


def test_cancel_interrupts_a_long_move_at_once(tmp_path):
    import time

    svc, bench = service(tmp_path, faults={"stage": {"seconds_per_mm": 1.0}})  # homing takes ~40 s
    try:
        job_id = svc.start_scan(SCAN)
        for st in svc.subscribe(timeout=10):
            if st["state"] == "homing" and st["message"] == "homing the stage":
                break
        time.sleep(0.2)
        t0 = time.monotonic()
        svc.cancel()
        assert time.monotonic() - t0 < 5
        job = svc.job(job_id)
        assert job["status"] == "cancelled", job["reason"]
        assert "stop" in bench.last.stage.calls and bench.last.light.on is False
    finally:
        svc.close()


PLATEAU = {**SCAN, "name": "plateau", "surface": "plateau", "levels_to_mm": 26.0, "levels_from_mm": 20.0}


def _levels(svc, job_id):
    import json

    frames = json.loads(svc.job_file(job_id, "scan/scan.json").read_text())["frames"]
    return [(f["level_mm"], f.get("refines")) for f in frames]


def test_a_scan_cut_while_refining_a_step_finishes_the_bisection_when_resumed(tmp_path):
    """The plateau's flat top comes out at once between 26 and 24 mm: the runner bisects that
    step (vision/refine.py). Cancelled in the middle of it, the resumed scan first takes the
    refinement frames an uninterrupted scan takes, then carries on down."""
    ref_svc, _ = service(tmp_path / "ref")
    try:
        ref = wait_final(ref_svc, ref_svc.start_scan(PLATEAU), timeout=400)
        want = _levels(ref_svc, ref["id"])
    finally:
        ref_svc.close()
    assert [lv for lv, r in want if r] and all(r == [26.0, 24.0] for lv, r in want if r)
    svc, bench = service(tmp_path, faults={"stage": {"seconds_per_mm": 0.05}})
    try:
        job_id = svc.start_scan(PLATEAU)
        for st in svc.subscribe(timeout=30):
            if st["levels_done"] >= 4:  # 26, 24 and two of the step's bisection
                break
        svc.cancel()
        assert svc.job(job_id)["status"] == "cancelled"
        assert 4 <= svc.job(job_id)["levels_done"] < len(want)
        svc.resume(job_id)
        job = wait_final(svc, job_id, timeout=400)
        assert job["status"] == "done", job["reason"]
        assert _levels(svc, job_id) == want
        assert audit(svc.store) == []
    finally:
        svc.close()


def _following_children():
    """This process's children that are processing children following a capture."""
    from pathlib import Path

    pids = []
    for task in Path("/proc/self/task").iterdir():
        pids += (task / "children").read_text().split()
    out = []
    for pid in pids:
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"appliance.daemon.processing_child" in cmd and b"--follow" in cmd:
            out.append(pid)
    return out


def test_the_childs_result_is_taken_when_it_ends_not_on_the_next_poll(tmp_path, monkeypatch):
    from appliance.daemon.processing import child_process

    # a stand-in for the processing child: it answers as the real one does, at once
    (tmp_path / "quick_child.py").write_text('import json\nprint(json.dumps({"outputs": []}))\n')
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    t = time.monotonic()
    result = child_process(tmp_path, tmp_path, {}, poll_s=30.0, module="quick_child")
    assert result["outputs"] == [] and "cpu_s" in result
    assert time.monotonic() - t < 10.0  # polled, it came 30 s after the start


def test_the_child_that_followed_the_capture_gives_what_inkslice_process_gives(tmp_path):
    from appliance.daemon.processing import child_process

    svc, _ = service(tmp_path, faults={"stage": {"seconds_per_mm": 0.05}}, processor=child_process)
    try:
        job_id = svc.start_scan({**SCAN, "pipeline": "inkslice"})
        seen_following = False
        for st in svc.subscribe(timeout=120):
            if st["state"] == "scanning" and (st.get("levels_done") or 0) >= 3:
                seen_following = seen_following or bool(_following_children())
            if st["state"] in ("done", "failed", "cancelled"):
                break
        job = wait_final(svc, job_id)
        assert job["status"] == "done", job["reason"]
        assert seen_following  # the child was there while the frames came in
        ref = tmp_path / "ref"
        process_scan(svc.store.job_dir(job_id) / "scan", ref, pipeline="inkslice")
        assert (ref / "heightmap.csv").read_bytes() == svc.job_file(job_id, "heightmap.csv").read_bytes()
        assert _following_children() == []
    finally:
        svc.close()


def test_a_scan_cancelled_during_its_capture_leaves_no_processing_child(tmp_path):
    from appliance.daemon.processing import child_process

    svc, _ = service(tmp_path, faults={"stage": {"seconds_per_mm": 0.05}}, processor=child_process)
    try:
        job_id = svc.start_scan({**SCAN, "pipeline": "inkslice"})
        for st in svc.subscribe(timeout=120):
            if st["state"] == "scanning" and (st.get("levels_done") or 0) >= 2 and _following_children():
                svc.cancel()
                break
        assert wait_final(svc, job_id)["status"] == "cancelled"
        assert _following_children() == []
    finally:
        svc.close()
