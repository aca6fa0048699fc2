"""Where the data lives: one rule (appliance/datadir.py) for the daemon, the web and the commands."""

from __future__ import annotations

from pathlib import Path

from appliance.commands import calibrate
from appliance.datadir import data_dir


def test_the_data_option_comes_first(monkeypatch, tmp_path):
    monkeypatch.setenv("INKSLICE_DATA", str(tmp_path / "env"))
    assert data_dir(tmp_path / "given", box=tmp_path) == tmp_path / "given"


def test_then_the_environment_as_the_systemd_units_set_it(monkeypatch, tmp_path):
    monkeypatch.setenv("INKSLICE_DATA", str(tmp_path / "env"))
    assert data_dir(None, box=tmp_path) == tmp_path / "env"


def test_then_the_box_folder_when_it_exists(monkeypatch, tmp_path):
    monkeypatch.delenv("INKSLICE_DATA", raising=False)
    assert data_dir(None, box=tmp_path) == tmp_path


def test_else_the_users_own_share_folder(monkeypatch, tmp_path):
    monkeypatch.delenv("INKSLICE_DATA", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert data_dir(None, box=tmp_path / "no-such-box") == tmp_path / "home" / ".local" / "share" / "inkslice"


def test_calibrate_writes_where_the_daemon_reads(monkeypatch, tmp_path):
    monkeypatch.setenv("INKSLICE_DATA", str(tmp_path / "data"))
    assert (
        calibrate.default_out() == data_dir() / "calibration.json" == Path(tmp_path / "data/calibration.json")
    )
