"""The box tells a webhook when a job finishes or fails, and a backup of settings and calibration
taken on one data folder restores the same settings and calibration on another."""

import json
import threading
from http.server import BaseHTTPRequestHandler, HTTPServer

import pytest
from daemon_helpers import SCAN, service, wait_final
from polling import wait_until

from appliance.cli import main as cli_main
from appliance.daemon import settings as S
from appliance.daemon.commissioned import in_force
from appliance.errors import InkSliceError, SettingError


@pytest.fixture
def receiver():
    """A webhook receiver on loopback: every POST's headers and JSON body, in order."""
    got = []

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):
            body = self.rfile.read(int(self.headers["Content-Length"]))
            got.append(
                {
                    "auth": self.headers.get("Authorization"),
                    "type": self.headers.get("Content-Type"),
                    "body": json.loads(body),
                }
            )
            self.send_response(204)
            self.end_headers()

        def log_message(self, *a):
            pass

    server = HTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_port}/hook", got
    server.shutdown()


def test_a_webhook_receives_finished_and_failed_events(tmp_path, receiver):
    url, got = receiver
    outcome = {"fail": False}

    def processor(scan, out, options, stop):
        if outcome["fail"]:
            raise InkSliceError(scan, "no waterline found in any frame")
        from appliance.daemon.processing import in_process

        return in_process(scan, out, options, stop)

    svc, _ = service(tmp_path, processor=processor)
    try:
        svc.update_settings({"webhook_url": url, "webhook_token": "s3cret"})
        done = wait_final(svc, svc.start_scan(SCAN))
        assert done["status"] == "done"
        wait_until(lambda: len(got) >= 1, what="the first webhook call")
        outcome["fail"] = True
        failed = wait_final(svc, svc.start_scan({**SCAN, "name": "second"}))
        assert failed["status"] == "failed"
        wait_until(lambda: len(got) >= 2, what="the second webhook call")
    finally:
        svc.close()
    assert [g["body"]["event"] for g in got] == ["finished", "failed"]
    first, second = (g["body"] for g in got)
    assert first["job_id"] == done["id"] and first["name"] == "cone" and first["status"] == "done"
    assert first["title"] == "InkSlice: job finished (cone)" and first["message"] == "cone is done"
    assert second["job_id"] == failed["id"] and "no waterline" in second["message"]
    assert all(g["auth"] == "Bearer s3cret" and g["type"] == "application/json" for g in got)
    assert svc.webhook.last()["ok"] is True


def test_no_webhook_address_sends_nothing_and_a_dead_receiver_fails_no_job(tmp_path):
    svc, _ = service(tmp_path)
    try:
        assert svc.webhook.send("finished", None, "x") is False  # the default: no address
        svc.update_settings({"webhook_url": "http://127.0.0.1:9/nobody-listens"})
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "done"
        wait_until(svc.webhook.last, 10, what="the webhook's attempt", every=0.05)
        assert svc.webhook.last()["ok"] is False and svc.webhook.last()["problem"]
    finally:
        svc.close()


def calibrate(store):
    """A commissioned box's history: level zero, the tank, an ink change, the meniscus."""
    store.add_calibration(
        {"kind": "level_zero", "method": "guided", "result": {"level_at_home_mm": 57.25}}, when=1e9
    )
    store.add_calibration({"kind": "tank", "method": "typed", "result": {"area_mm2": 22500.0}}, when=1e9 + 10)
    store.add_calibration({"kind": "ink_changed"}, when=1e9 + 20)
    store.add_calibration({"kind": "meniscus", "method": "ball", "result": {"a": 1.5}}, when=1e9 + 30)


def test_a_backup_restored_on_another_data_folder_gives_the_same_settings_and_calibration(tmp_path):
    one, _ = service(tmp_path / "one")
    two, _ = service(tmp_path / "two")
    try:
        calibrate(one.store)
        one.update_settings(
            {"level_at_home_mm": 57.25, "dialect": "fanuc", "grid": 80, "webhook_url": "https://x/y"}
        )
        two.update_settings({"grid": 12})  # whatever was there goes
        two.store.add_calibration({"kind": "tank", "method": "typed", "result": {"area_mm2": 1.0}})
        doc = json.loads(json.dumps(one.backup()))  # as a downloaded file carries it
        assert two.restore(doc) == {"settings": len(S.DEFAULTS), "calibration": 4}
        assert two.settings() == one.settings()
        assert two.store.calibrations() == one.store.calibrations()
        assert in_force(two.store) == in_force(one.store)
        assert two.export_commissioning()["results"] == one.export_commissioning()["results"]
        assert [s["status"] for s in two.commissioning()["steps"]] == [
            s["status"] for s in one.commissioning()["steps"]
        ]
    finally:
        one.close()
        two.close()


def test_a_bad_backup_is_refused_and_changes_nothing(tmp_path):
    svc, _ = service(tmp_path)
    try:
        calibrate(svc.store)
        before = (svc.settings(), svc.store.calibrations())
        good = svc.backup()
        for bad, says in [
            ({"format": "x"}, "not an InkSlice backup"),
            ({**good, "settings": {**good["settings"], "grid": 1}}, "grid: must be a whole number"),
            ({**good, "calibration": [{"kind": "tank"}]}, "calibration record 0 has no date"),
        ]:
            with pytest.raises(SettingError) as e:
                svc.restore(bad)
            assert says in str(e.value)
        assert (svc.settings(), svc.store.calibrations()) == before
    finally:
        svc.close()


def test_the_cli_backs_up_and_restores_a_data_folder(tmp_path, capsys):
    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir()
    two.mkdir()
    assert cli_main(["settings", "set", "dialect=grbl", "--data", str(one)]) == 0
    assert cli_main(["settings", "backup", "-o", str(tmp_path / "b.json"), "--data", str(one)]) == 0
    assert cli_main(["settings", "restore", str(tmp_path / "b.json"), "--data", str(two)]) == 0
    capsys.readouterr()
    assert cli_main(["settings", "show", "--data", str(two)]) == 0
    assert 'dialect = "grbl"' in capsys.readouterr().out


def test_the_settings_page_test_button_reaches_the_receiver_through_the_web(tmp_path, receiver):
    from web_helpers import login

    from appliance.web import create_app

    url, got = receiver
    svc, _ = service(tmp_path)
    try:
        app = create_app(svc, {"data_dir": str(tmp_path / "web")})
        app.config["TESTING"] = True
        c = app.test_client()
        h = {"X-CSRF-Token": login(c, app.config["FIRST_RUN_PASSWORD"])}
        assert c.post("/api/webhook/test", headers=h).get_json() == {
            "ok": False,
            "problem": "no webhook address is set",
        }
        c.patch("/api/settings", json={"webhook_url": url}, headers=h)
        assert c.post("/api/webhook/test", headers=h).get_json() == {"ok": True, "problem": ""}
        assert got[-1]["body"]["event"] == "test" and got[-1]["auth"] is None
    finally:
        svc.close()
