"""The bench's front panel: short/long presses, the long press's USB copy, what the display says."""

import json
import time
from pathlib import Path

import pytest
from daemon_helpers import SCAN, wait_final
from polling import wait_until

from appliance.daemon.service import BenchService
from appliance.errors import DeviceError
from appliance.hw.gpio import PressTimer
from appliance.hw.usb import UsbExporter
from appliance.sim.fakes import FakeBench


def light_processor(scan_folder, out_folder, options, stop=None):
    """Outputs shaped like process_scan's, at no cost: the panel, not the science, is tested here."""
    from appliance.atomicio import write_text

    n = len(json.loads((Path(scan_folder) / "scan.json").read_text())["frames"])
    write_text(Path(out_folder) / "toolpath.gcode", f"G21 G90\nF800\n(levels {n})\nG1 X1 Y2 Z3\nM2\n")
    write_text(Path(out_folder) / "heightmap.csv", "x,y,z\n0.0000,0.0000,1.0000\n")
    return {"outputs": ["heightmap.csv", "toolpath.gcode"]}


def test_press_timer_tells_short_from_long():
    t = PressTimer(2.0)
    assert t.edge(True, 10.0) is None and t.check(11.0) is None
    assert t.edge(False, 11.5) == "short"
    assert t.edge(True, 20.0) is None
    assert t.check(21.9) is None and t.check(22.0) == "long"  # reported while still held
    assert t.check(23.0) is None and t.edge(False, 24.0) is None  # once, and the release says nothing
    assert t.edge(True, 30.0) is None and t.edge(False, 32.5) == "long"  # polled only after the release
    assert t.edge(False, 40.0) is None  # a release without a press (held at start)


@pytest.fixture
def bench(tmp_path):
    media = tmp_path / "media"
    stick = media / "STICK"
    stick.mkdir(parents=True)
    mounts = tmp_path / "mounts"
    mounts.write_text("")

    def unmount(s):
        """What inkslice-stick@.service's stop does, as far as the mount table shows it."""
        mounts.write_text("".join(l for l in mounts.read_text().splitlines(True) if f" {s.mount} " not in l))

    usb = UsbExporter(mounts_file=mounts, roots=(str(media),), sys_root=tmp_path / "nosys", unmount=unmount)
    factory = FakeBench("cone")
    svc = BenchService(tmp_path / "data", factory, processor=light_processor, panel_interval_s=0.02, usb=usb)
    yield svc, factory.panel, stick, mounts
    svc.close()


def notice_code(svc):
    n = svc.state()["notice"]
    return n and n["code"] not in ("copying",) and n["code"]


def long_press(svc, panel):
    before = svc.state()["notice"]
    panel.button.long_press()
    wait_until(lambda: svc.state()["notice"] not in (None, before) and notice_code(svc), what="a USB outcome")
    return svc.state()["notice"]


def test_long_press_copies_the_latest_gcode_to_the_stick_and_says_so(bench):
    svc, panel, stick, mounts = bench
    # nothing finished yet
    n = long_press(svc, panel)
    assert (n["code"], n["ok"]) == ("no_gcode", False)
    wait_until(lambda: panel.display.lines[:1] == ["USB: NOTHING"], what="the display")
    assert svc.state()["state"] == "idle"  # a long press never starts a scan

    job_id = svc.start_scan(SCAN)
    assert wait_final(svc, job_id)["status"] == "done"
    gcode = svc.job_file(job_id, "toolpath.gcode").read_bytes()

    # no stick in
    n = long_press(svc, panel)
    assert n["code"] == "no_stick" and "no USB stick" in n["text"]
    wait_until(lambda: panel.display.lines[:1] == ["USB: NO STICK"], what="the display")

    # a stick in: copied, verified, unmounted, and the operator is told it is safe to pull it
    mounts.write_text(f"/dev/sdb1 {stick} vfat rw,relatime 0 0\n")
    n = long_press(svc, panel)
    assert n["ok"] and n["code"] == "copied", n
    name = f"{job_id}-toolpath.gcode"
    assert (stick / "inkslice" / name).read_bytes() == gcode
    assert n["text"] == f"copied {name} to the USB stick and unmounted it, safe to remove"
    assert mounts.read_text() == ""
    lines = wait_until(
        lambda: panel.display.lines[0] == "USB COPY OK" and panel.display.lines, what="the display"
    )
    assert lines[1] == name[:18] and lines[2] == "safe to remove"
    assert [p.name for p in (stick / "inkslice").iterdir()] == [name]  # no temporary file left
    # the event log keeps every outcome, newest first
    usb_events = [e["message"] for e in svc.events() if e["kind"] == "usb"]
    assert (
        usb_events[0] == n["text"] and "no USB stick" in usb_events[1] and "no finished job" in usb_events[2]
    )

    # a short press gives the display back to the bench and starts a scan as before
    panel.button.press()
    wait_until(lambda: svc.state()["state"] in ("homing", "scanning", "processing", "done"), what="a scan")
    wait_until(lambda: panel.display.lines[0] != "USB COPY OK", what="the display back")
    svc.cancel()


def test_the_long_press_takes_the_newest_finished_job_with_gcode(bench):
    """Job picking is the daemon's: it knows its own job rows (hw/usb.py only copies)."""
    svc, *_ = bench
    assert svc.latest_gcode() is None
    for job_id, status, outputs in (
        ("1-old", "done", ["toolpath.gcode", "report.md"]),
        ("2-grbl", "done", ["report.md", "toolpath-grbl.nc"]),
        ("3-ball", "done", ["reference.json", "heightmap.csv"]),
        ("4-now", "scanning", []),
    ):
        svc.store.create_job(job_id, job_id, svc.settings(), {}, 1)
        svc.store.update_job(job_id, status=status, outputs=outputs)
        time.sleep(0.01)
    assert svc.latest_gcode() == ("2-grbl", "toolpath-grbl.nc")
    svc.store.update_job("2-grbl", outputs=["toolpath.gcode", "toolpath-grbl.nc"])
    assert svc.latest_gcode() == ("2-grbl", "toolpath.gcode")  # the finishing program first


def test_long_press_during_a_scan_copies_and_does_not_stop_it(bench):
    svc, panel, stick, mounts = bench
    first = svc.start_scan(SCAN)
    assert wait_final(svc, first)["status"] == "done"
    mounts.write_text(f"/dev/sdb1 {stick} vfat rw 0 0\n")
    second = svc.start_scan({**SCAN, "settle_s": 0.2})
    wait_until(lambda: svc.state()["state"] == "scanning", what="scanning")
    n = long_press(svc, panel)
    assert n["code"] == "copied" and first in n["text"]
    assert svc.state()["state"] in ("scanning", "processing", "done")  # still going
    assert wait_final(svc, second)["status"] == "done"


def test_a_stick_that_will_not_unmount_is_not_called_safe_to_remove(bench):
    svc, panel, stick, mounts = bench

    def busy(s):
        raise DeviceError(s.mount, "systemctl: Job for inkslice-stick@sdb1.service failed")

    svc.usb.unmount = busy
    job_id = svc.start_scan(SCAN)
    assert wait_final(svc, job_id)["status"] == "done"
    mounts.write_text(f"/dev/sdb1 {stick} vfat rw 0 0\n")
    n = long_press(svc, panel)
    assert (n["code"], n["ok"]) == ("still_mounted", False)
    assert (stick / "inkslice" / f"{job_id}-toolpath.gcode").is_file()  # the copy itself is there
    assert "could not unmount it (systemctl: Job for" in n["text"] and "safe to remove" not in n["text"]
    lines = wait_until(
        lambda: panel.display.lines[0] == "USB COPY OK" and panel.display.lines, what="the display"
    )
    assert lines[2] == "NOT unmounted"


def test_without_an_exporter_the_long_press_says_usb_is_off(tmp_path):
    factory = FakeBench("cone")
    svc = BenchService(tmp_path / "data", factory, processor=light_processor, panel_interval_s=0.02)
    try:
        n = long_press(svc, factory.panel)
        assert n["code"] == "off" and "switched off" in n["text"]
    finally:
        svc.close()


def test_gpio_button_maps_kernel_edges_to_presses(monkeypatch):
    """GpioButton.poll() on made-up edge events (no gpiochip here): rising = pressed (active low)."""
    from types import SimpleNamespace

    from gpiod.edge_event import EdgeEvent

    from appliance.hw import gpio

    class Req:
        def __init__(self):
            self.events = []

        def wait_edge_events(self, timeout):
            return bool(self.events)

        def read_edge_events(self):
            out, self.events = self.events, []
            return out

    def ev(kind, t):
        return SimpleNamespace(event_type=kind, timestamp_ns=int(t * 1e9))

    now = [100.0]
    monkeypatch.setattr(gpio.time, "monotonic", lambda: now[0])
    b = gpio.GpioButton.__new__(gpio.GpioButton)
    b._req, b._rising, b._timer = Req(), EdgeEvent.Type.RISING_EDGE, gpio.PressTimer(2.0)
    rise, fall = EdgeEvent.Type.RISING_EDGE, EdgeEvent.Type.FALLING_EDGE
    b._req.events = [ev(rise, 100.0), ev(fall, 100.3)]
    assert b.poll() == "short" and b.poll() is None
    b._req.events = [ev(rise, 101.0)]
    now[0] = 101.5
    assert b.poll() is None  # still held, not yet long
    now[0] = 103.1
    assert b.poll() == "long"  # held 2.1 s: reported before the release
    b._req.events = [ev(fall, 104.0)]
    assert b.poll() is None
