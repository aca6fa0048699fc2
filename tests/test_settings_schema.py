"""One settings schema: every setting says its type, unit, range or choices, help and group, and the
daemon, the web API and `inkslice settings` refuse the same bad value with the same sentence."""

import pytest
from daemon_helpers import service
from web_helpers import login

from appliance.cam.posts import DIALECT_NAMES
from appliance.cli import build_parser
from appliance.cli import main as cli_main
from appliance.daemon import settings as S
from appliance.errors import SettingError
from appliance.web import create_app


@pytest.mark.parametrize("setting", S.SCHEMA, ids=lambda s: s.key)
def test_every_setting_has_a_type_unit_range_or_choices_help_and_group(setting):
    assert setting.kind in S.KINDS
    assert setting.group in dict(S.GROUPS)
    assert setting.label and setting.label[0].isupper()
    assert len(setting.help) > 20 and setting.help.endswith((".", ")"))
    if setting.kind in ("number", "int"):
        assert setting.unit, "a number without its unit"
        assert setting.lo is not None and setting.hi is not None and setting.lo < setting.hi
        assert setting.step and setting.step > 0
    elif setting.kind in ("choice", "bool"):
        assert setting.unit == ""
        assert len(setting.allowed()) >= 2 and setting.default in setting.allowed()
    else:
        assert setting.pattern and setting.pattern_says
    # the default is itself a good value
    assert S.validate(S.DEFAULTS, {setting.key: setting.default})[setting.key] == setting.default


def test_the_schema_json_the_form_draws_holds_every_setting_once_in_its_group():
    doc = S.schema_json()
    assert [g["id"] for g in doc["groups"]] == [g for g, _ in S.GROUPS]
    keys = [item["key"] for g in doc["groups"] for item in g["settings"]]
    assert sorted(keys) == sorted(S.DEFAULTS)
    dialect = next(i for g in doc["groups"] for i in g["settings"] if i["key"] == "dialect")
    assert dialect["choices"] == list(DIALECT_NAMES)


def test_the_settings_know_every_dialect_the_toolpath_command_knows():
    toolpath = build_parser()._subparsers._group_actions[0].choices["toolpath"]
    cli = next(a for a in toolpath._actions if a.dest == "dialect").choices
    assert tuple(cli) == S.BY_KEY["dialect"].allowed() == DIALECT_NAMES
    assert len(DIALECT_NAMES) == 5
    for d in DIALECT_NAMES:
        assert S.validate(S.DEFAULTS, {"dialect": d})["dialect"] == d


# (key, as typed on the command line, as the web's JSON carries it)
BAD = [
    ("level_step_mm", "-1", -1),
    ("level_step_mm", "abc", "abc"),
    ("dialect", "heidenhain", "heidenhain"),
    ("grid", "2.5", 2.5),
    ("auto_resume", "yes", "yes"),
    ("webhook_url", "ftp://box/x", "ftp://box/x"),
    ("levels_to_mm", "500", 500),
    ("step_mode", "Fixed", "Fixed"),
    ("min_free_mb", "0", 0),
    ("no_such_setting", "1", 1),
]


@pytest.mark.parametrize("key,typed,value", BAD, ids=[f"{k}={t}" for k, t, _ in BAD])
def test_daemon_web_and_cli_refuse_a_bad_value_with_the_same_sentence(tmp_path, capsys, key, typed, value):
    svc, _ = service(tmp_path / "daemon")
    try:
        with pytest.raises(SettingError) as e:
            svc.update_settings({key: value})
        daemon_says = str(e.value)
        assert svc.settings() == S.DEFAULTS  # nothing changed

        app = create_app(svc, {"data_dir": str(tmp_path / "web")})
        app.config["TESTING"] = True
        c = app.test_client()
        csrf = login(c, app.config["FIRST_RUN_PASSWORD"])
        r = c.patch("/api/settings", json={key: value}, headers={"X-CSRF-Token": csrf})
        assert r.status_code == 400
        web_says = f"{r.get_json()['where']}: {r.get_json()['error']}"
    finally:
        svc.close()

    (tmp_path / "cli").mkdir()
    assert cli_main(["settings", "set", f"{key}={typed}", "--data", str(tmp_path / "cli")]) == 2
    cli_says = capsys.readouterr().err.strip()
    assert cli_says == f"inkslice: error: {daemon_says}"
    assert web_says == daemon_says
    assert daemon_says.startswith(f"{key}: ")


def test_the_cli_changes_a_setting_as_the_web_would(tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    assert (
        cli_main(["settings", "set", "dialect=mach3", "grid=40", "auto_resume=true", "--data", str(data)])
        == 0
    )
    capsys.readouterr()
    assert cli_main(["settings", "show", "--data", str(data)]) == 0
    shown = capsys.readouterr().out
    assert (
        'dialect = "mach3"' in shown
        and "grid = 40  [cells a side]" in shown
        and "auto_resume = true" in shown
    )


def test_every_setting_is_read_somewhere_outside_the_schema():
    """A setting validated but never read is a promise the box does not keep (a cross-check in
    settings.validate, like envelope_z_mm capping the top level, counts as a use)."""
    import re
    from pathlib import Path

    root = Path(S.__file__).resolve().parents[1]
    sources = [
        p.read_text()
        for p in root.rglob("*")
        if p.suffix in (".py", ".html", ".js") and p.name != "settings_schema.py"
    ]
    unread = [key for key in S.DEFAULTS if not any(re.search(rf"\b{key}\b", text) for text in sources)]
    assert unread == []


def test_a_settings_file_holding_removed_settings_still_loads_without_them(tmp_path, caplog):
    svc, _ = service(tmp_path)
    try:
        svc.store.save_settings(
            {"stepover_mm": 1.5, "feed_mm_min": 700.0, "envelope_x_mm": 300.0, "dialect": "grbl"}
        )
        with caplog.at_level("INFO", logger="inkslice.settings"):
            settings = svc.settings()
        assert settings["dialect"] == "grbl"  # what it still knows is kept
        assert not {"stepover_mm", "feed_mm_min", "envelope_x_mm", "envelope_y_mm"} & settings.keys()
        assert "'stepover_mm' is not one this version has" in caplog.text
        assert svc.update_settings({"level_step_mm": 0.5})["level_step_mm"] == 0.5  # and takes changes
        assert "stepover_mm" not in S.validate(settings, {})
    finally:
        svc.close()
