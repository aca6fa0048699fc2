"""The firmware as package data: where it builds, and `inkslice firmware` flashing through avrdude.
(tests/test_installed_copy.py does the same from an installed wheel.)"""

import os
import sys
from pathlib import Path

import pytest

from appliance import firmware
from appliance.cli import main as cli_main

needs_avr = pytest.mark.needs("avr-gcc")


def test_the_build_goes_to_a_cache_folder_of_its_own_never_into_the_sources(monkeypatch, tmp_path):
    monkeypatch.delenv("INKSLICE_FIRMWARE_BUILD", raising=False)
    monkeypatch.delenv("INKSLICE_FIRMWARE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    here = firmware.build_dir()
    assert here.parent == tmp_path / "cache" / "inkslice" and not here.is_relative_to(firmware.SOURCE)
    assert firmware.codes_path() == firmware.SOURCE / "codes.def" and firmware.codes_path().is_file()
    monkeypatch.setenv("INKSLICE_FIRMWARE_DIR", str(tmp_path / "other-tree"))
    assert firmware.build_dir() != here  # another tree never reuses these objects
    monkeypatch.setenv("INKSLICE_FIRMWARE_BUILD", str(tmp_path / "here"))
    assert firmware.build_dir() == tmp_path / "here"


def fake_avrdude(folder: Path, body: str) -> None:
    folder.mkdir()
    (folder / "avrdude").write_text(f"#!{sys.executable}\nimport sys\n{body}\n")
    (folder / "avrdude").chmod(0o755)


@needs_avr
def test_flash_without_avrdude_is_one_clear_line(monkeypatch, capsys):
    monkeypatch.setattr(firmware.shutil, "which", lambda name: None)
    assert cli_main(["firmware", "flash", "--port", "/dev/ttyACM0"]) == 2
    assert capsys.readouterr().err == "inkslice: error: avrdude: not installed (apt-get install avrdude)\n"


@needs_avr
def test_a_failing_avrdude_names_the_port_and_says_why(monkeypatch, tmp_path, capsys):
    fake_avrdude(
        tmp_path / "bin",
        "print('avrdude: stk500_recv(): programmer is not responding', file=sys.stderr); sys.exit(1)",
    )
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}:{os.environ['PATH']}")
    assert cli_main(["firmware", "flash", "--port", "/dev/ttyACM0"]) == 2
    assert capsys.readouterr().err == (
        "inkslice: error: /dev/ttyACM0: avrdude failed: "
        "avrdude: stk500_recv(): programmer is not responding\n"
    )


@needs_avr
def test_dry_run_prints_the_avrdude_line_with_the_built_hex(capsys):
    assert cli_main(["firmware", "flash", "--dry-run", "--baud", "57600"]) == 0
    line = capsys.readouterr().out.strip()
    hex_file = firmware.build_dir() / firmware.HEX
    assert line == f"avrdude -p m328p -c arduino -P /dev/inkslice-stage -b 57600 -D -U flash:w:{hex_file}:i"
    assert hex_file.read_text().startswith(":")
