"""The settings form drawn from the schema, and the system page: figures, logs, support bundle,
backup and restore through the web, on the daemon's real BenchService (fake devices)."""

import io
import json
import re
import zipfile

import pytest
from daemon_helpers import service
from web_helpers import login

from appliance import logfiles
from appliance.cam.posts import DIALECT_NAMES
from appliance.daemon import settings as S
from appliance.web import create_app


def web_on(tmp_path, name="box"):
    svc, _ = service(tmp_path / name)
    app = create_app(
        svc, {"data_dir": str(tmp_path / name / "data"), "bench_data_dir": str(tmp_path / name / "data")}
    )
    app.config["TESTING"] = True
    c = app.test_client()
    csrf = login(c, app.config["FIRST_RUN_PASSWORD"])
    return svc, c, {"X-CSRF-Token": csrf}


@pytest.fixture
def web(tmp_path):
    svc, c, h = web_on(tmp_path)
    yield svc, c, h
    svc.close()


def test_the_settings_form_has_a_proper_control_help_and_unit_for_every_setting(web):
    _, c, _ = web
    page = c.get("/settings").get_data(as_text=True)
    for gid, title in S.GROUPS:
        assert f'id="group-{gid}"' in page and f'<legend class="sr-only">{title}</legend>' in page
    for s in S.SCHEMA:
        assert f'id="help-{s.key}"' in page, s.key  # "What is this?" on tap
        control = re.search(rf'<(input|select)[^>]*id="set-{s.key}"[^>]*>', page)
        assert control, s.key
        tag = control.group(0)
        if s.kind == "choice":
            assert tag.startswith("<select")
        elif s.kind == "bool":
            assert 'type="checkbox"' in tag and 'role="switch"' in tag
        elif s.kind in ("number", "int"):
            assert 'type="number"' in tag and f'step="{s.step}"' in tag
            assert f'<span class="unit" aria-hidden="true">{s.unit}</span>' in page
            assert f'<label for="set-{s.key}">{s.label} <span class="muted">({s.unit})</span></label>' in page
    dialects = re.search(r'<select[^>]*id="set-dialect".*?</select>', page, re.S).group(0)
    assert re.findall(r'<option value="([a-z0-9]+)"', dialects) == list(DIALECT_NAMES)
    assert 'type="password"' in re.search(r'<input[^>]*id="set-webhook_token"[^>]*>', page).group(0)


def test_the_web_takes_every_dialect_the_cli_knows(web):
    _, c, h = web
    for d in DIALECT_NAMES:
        r = c.patch("/api/settings", json={"dialect": d}, headers=h)
        assert r.status_code == 200 and r.get_json()["dialect"] == d


def test_the_system_page_shows_version_uptimes_and_disk(web):
    _, c, _ = web
    info = c.get("/api/system").get_json()
    assert info["version"] and info["daemon_uptime_s"] >= 0 and info["web_uptime_s"] >= 0
    assert 0 < info["disk"]["free_bytes"] <= info["disk"]["total_bytes"]
    page = c.get("/system").get_data(as_text=True)
    assert f'<dd id="sys-version">{info["version"]}</dd>' in page and "GB free of" in page


def test_the_logs_are_the_last_thousand_lines_and_download_as_a_file(web, tmp_path):
    _, c, _ = web
    log = logfiles.path(tmp_path / "box" / "data", "daemon")
    log.parent.mkdir(parents=True, exist_ok=True)
    log.write_text("".join(f"line {i}\n" for i in range(1500)))
    r = c.get("/api/logs/daemon")
    lines = r.get_data(as_text=True).splitlines()
    assert len(lines) == 1000 and lines[0] == "line 500" and lines[-1] == "line 1499"
    d = c.get("/api/logs/daemon?download=1")
    assert "attachment" in d.headers["Content-Disposition"] and d.data == r.data
    assert c.get("/api/logs/web").status_code == 200
    assert c.get("/api/logs/passwd").status_code == 404


def test_a_log_file_records_this_process_log_lines(tmp_path):
    import logging

    path = logfiles.log_to_file(tmp_path, "web")
    try:
        logging.getLogger("inkslice.web").warning("a line for the system page")
        assert "a line for the system page" in logfiles.tail(tmp_path, "web")
    finally:
        root = logging.getLogger()
        for h in [h for h in root.handlers if getattr(h, "baseFilename", None) == str(path)]:
            root.removeHandler(h)
            h.close()


def test_the_support_bundle_holds_logs_settings_and_calibration_but_no_secret(web, tmp_path):
    svc, c, h = web
    secret_url = "https://ntfy.sh/inkslice-topic-9f3a2b"
    assert (
        c.patch(
            "/api/settings", json={"webhook_url": secret_url, "webhook_token": "tok-77a1c9"}, headers=h
        ).status_code
        == 200
    )
    svc.store.add_calibration({"kind": "tank", "method": "typed", "result": {"area_mm2": 22500.0}})
    c.post("/api/tokens", json={"name": "script"}, headers=h)
    r = c.get("/api/support.zip")
    assert r.status_code == 200 and "attachment" in r.headers["Content-Disposition"]
    z = zipfile.ZipFile(io.BytesIO(r.data))
    assert {
        "logs/daemon.log",
        "logs/web.log",
        "settings.json",
        "calibration.json",
        "system.json",
        "events.json",
    } <= set(z.namelist())
    settings = json.loads(z.read("settings.json"))
    assert settings["webhook_url"] == "https://ntfy.sh/..." and settings["webhook_token"] == "(set)"
    assert json.loads(z.read("calibration.json"))[0]["result"] == {"area_mm2": 22500.0}
    everything = b"".join(z.read(n) for n in z.namelist())
    assert b"inkslice-topic-9f3a2b" not in everything and b"tok-77a1c9" not in everything
    admin = (tmp_path / "box" / "data" / "web" / "admin.json").read_bytes()
    for value in json.loads(admin).values():  # the password hash and its salt
        if isinstance(value, str) and len(value) > 8:
            assert value.encode() not in everything


def test_a_backup_downloaded_from_one_box_restores_the_same_settings_and_calibration_on_another(tmp_path):
    one, c1, h1 = web_on(tmp_path, "one")
    two, c2, h2 = web_on(tmp_path, "two")
    try:
        one.store.add_calibration(
            {"kind": "level_zero", "method": "guided", "result": {"level_at_home_mm": 58.5}}
        )
        one.store.add_calibration({"kind": "tank", "method": "typed", "result": {"area_mm2": 22000.0}})
        c1.patch(
            "/api/settings",
            json={"level_at_home_mm": 58.5, "dialect": "mach3", "auto_resume": True},
            headers=h1,
        )
        r = c1.get("/api/backup")
        assert "attachment" in r.headers["Content-Disposition"]
        out = c2.post("/api/restore", data=r.data, content_type="application/json", headers=h2)
        assert out.status_code == 200 and out.get_json()["calibration"] == 2
        assert c2.get("/api/settings").get_json() == c1.get("/api/settings").get_json()
        assert (
            c2.get("/api/commissioning").get_json()["steps"]
            == c1.get("/api/commissioning").get_json()["steps"]
        )
        bad = c2.post("/api/restore", json={"format": "something else"}, headers=h2)
        assert bad.status_code == 400 and "not an InkSlice backup" in bad.get_json()["error"]
    finally:
        one.close()
        two.close()


def test_the_report_shows_plain_names_with_units_and_an_explanation_on_tap():
    from appliance.web.report import readable

    groups = readable(
        {
            "seed:lsq3": {"n": 2070, "Ea": 0.5, "matching": 98.4},
            "inkslice:fit": {
                "n": 2070,
                "Ea": 0.0722,
                "max_error": 0.9,
                "Ep_printed": 0.2,
                "normaliser": 49.81,
            },
        }
    )
    assert [g["title"] for g in groups] == [
        "InkSlice regularised fit",
        "Least squares, degree 3 (seed)",
    ]
    rows = {r["key"]: r for r in groups[0]["rows"]}
    assert [r["name"] for r in groups[0]["rows"]][:2] == ["Mean error", "Largest error"]
    assert rows["Ea"]["unit"] == "mm" and rows["n"]["unit"] == "cells" and rows["Ep_printed"]["unit"] == "%"
    assert all(len(r["help"]) > 30 for r in groups[0]["rows"])
    flat = readable({"rms_mm": 0.01, "levels": 41})
    assert flat[0]["title"] == "Statistics" and [r["name"] for r in flat[0]["rows"]] == ["rms_mm", "levels"]


def test_the_job_page_shows_the_report_in_plain_words(web):
    from daemon_helpers import wait_final
    from test_web_real_service import SCAN, light_processor

    svc, c, _ = web
    svc.processor = light_processor
    job = wait_final(svc, svc.start_scan(SCAN))
    page = c.get(f"/jobs/{job['id']}").get_data(as_text=True)
    assert "<caption>InkSlice regularised fit</caption>" in page
    assert "<summary>Mean error</summary>" in page and "0.0722 mm" in page
    assert (
        "<summary>Spread of the error</summary>" in page
        and "inkslice:fit" not in page.split("<caption>")[1][:40]
    )


def test_the_job_pictures_say_what_they_show():
    from appliance.web.report import picture_caption

    assert (
        picture_caption("error_inkslice_fit.png")
        == "Where InkSlice regularised fit differs from the true part (error in mm, scale on the right)"
    )
    assert "Least squares, degree 3 (seed)" in picture_caption("error_lsq3.png")
    assert picture_caption("uncertainty.png").startswith("How sure each cell")
    assert picture_caption("error.png") == "error.png"  # a picture we do not know keeps its name
