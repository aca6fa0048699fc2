"""Lint, layout and types, as CI checks them; `make lint` runs the same commands.

- ruff: the Python tree has no lint finding and is laid out as `ruff format` lays it out
  (rules and line length in pyproject.toml);
- mypy: the typed rooms (pyproject.toml's [tool.mypy] files: the pure science and the
  daemon's facade) type-check, one test per room so a failure names its room;
- clang-format: the firmware's C sources are laid out as its .clang-format says.

Each runs the tool on the checkout and fails with the tool's own report.
"""

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
FIRMWARE = REPO / "appliance" / "firmware" / "stepper"
TYPED_ROOMS = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["mypy"]["files"]


def run(*cmd, cwd=REPO):
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=600)
    return r.returncode, (r.stdout + r.stderr).strip()


def test_ruff_finds_nothing_in_the_python_tree():
    code, report = run(str(BIN / "ruff"), "check", "--no-cache")
    assert code == 0, f"ruff check (fix with `ruff check --fix` or by hand):\n{report}"


def test_the_python_tree_is_laid_out_by_ruff_format():
    code, report = run(str(BIN / "ruff"), "format", "--check", "--no-cache")
    assert code == 0, f"run `ruff format` on:\n{report}"


@pytest.mark.parametrize("room", TYPED_ROOMS)
def test_the_typed_room_type_checks(room):
    code, report = run(sys.executable, "-m", "mypy", room)
    assert code == 0, f"mypy {room}:\n{report}"


def test_the_typed_rooms_are_the_science_and_the_facade():
    """The rooms issue 22 put under mypy; one leaves the list only with a reason written here."""
    want = {"appliance/vision", "appliance/surface", "appliance/cam", "appliance/daemon/facade.py"}
    assert set(TYPED_ROOMS) == want


@pytest.mark.needs("clang-format")
def test_the_firmware_is_laid_out_by_clang_format():
    assert (FIRMWARE / ".clang-format").is_file()
    code, report = run("make", "-s", "-C", str(FIRMWARE), "format-check")
    assert code == 0, f"run `make -C {FIRMWARE.relative_to(REPO)} format`:\n{report}"
