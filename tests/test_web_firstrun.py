"""The first-run password reaches the bench's display (fake) through the daemon, until the first login."""

import os
import stat

from daemon_helpers import SCAN, wait_final
from polling import wait_until
from test_daemon_panel import light_processor
from web_helpers import csrf_of, login

from appliance.daemon import firstrun
from appliance.daemon.service import BenchService
from appliance.sim.fakes import FakeBench
from appliance.web import create_app


def wait_lines(display, pred, timeout=5.0):
    """The display's lines once `pred` holds for them."""
    return wait_until(
        lambda: display.lines if display.lines and pred(display.lines) else None,
        timeout,
        what=lambda: f"other lines on the display than {display.lines}",
    )


def test_first_run_password_is_shown_on_the_bench_until_the_first_login(tmp_path):
    daemon_data = tmp_path / "var-lib-inkslice"
    factory = FakeBench("cone")
    svc = BenchService(daemon_data, factory, processor=light_processor, panel_interval_s=0.02)
    display = factory.panel.display
    try:
        # idle daemon, no web yet: the usual status lines
        wait_lines(display, lambda l: l[0] == "IDLE")
        # the web server (its own unit; the daemon's data folder is shared) makes the password
        cfg = {"data_dir": str(tmp_path / "web-data"), "bench_data_dir": str(daemon_data)}
        app = create_app(svc, cfg)
        password = app.config["FIRST_RUN_PASSWORD"]
        assert password
        left = daemon_data / firstrun.FILE
        assert stat.S_IMODE(os.stat(left).st_mode) == 0o600
        lines = wait_lines(display, lambda l: l[0] == "FIRST LOGIN")
        assert lines[2] == password and len(lines) == 4
        # the password is for the screen only: never in the state the API serves
        assert password not in str(svc.state())

        # a scan's progress takes the screen while it runs, then the password comes back
        job = svc.start_scan({**SCAN, "settle_s": 0.1})
        wait_lines(display, lambda l: l[0] in ("HOMING", "SCANNING"))
        assert wait_final(svc, job)["status"] == "done"
        wait_lines(display, lambda l: l[0] == "FIRST LOGIN")

        # a web restart before anyone logged in keeps the same password on the screen
        app = create_app(svc, cfg)
        assert app.config["FIRST_RUN_PASSWORD"] is None and left.exists()

        # a wrong password changes nothing
        c = app.test_client()
        r = c.post("/login", data={"password": "not-it-at-all", "csrf_token": csrf_of(c)})
        assert r.status_code == 401 and left.exists()
        # the first login clears it: file gone, display back to the bench's state
        login(c, password)
        assert not left.exists()
        wait_lines(display, lambda l: l[0] == "DONE")
        # and a second app start does not bring it back
        assert create_app(svc, cfg).config["FIRST_RUN_PASSWORD"] is None and not left.exists()

        # the demo's --new-password hands over a fresh one
        app = create_app(svc, {**cfg, "reset_password": True})
        fresh = app.config["FIRST_RUN_PASSWORD"]
        assert fresh != password
        assert wait_lines(display, lambda l: l[0] == "FIRST LOGIN")[2] == fresh
    finally:
        svc.close()


def test_the_hand_over_file(tmp_path):
    p = firstrun.Pending(tmp_path)
    assert p.pending() is None
    firstrun.hand_over(tmp_path, "abcd-efgh-ijkl")
    assert p.pending() == "abcd-efgh-ijkl"
    firstrun.hand_over(tmp_path, "mnop-qrst-uvwx")
    assert p.pending() == "mnop-qrst-uvwx"
    assert firstrun.done(tmp_path) is True and p.pending() is None
    assert firstrun.done(tmp_path) is False
    assert [f.name for f in tmp_path.iterdir()] == []  # no temporary file left
