"""What every test file shares: the firmware fixtures, and the rule for tests that need a
program from outside Python.

A test that needs simavr, systemd, chromium, ... says so with `@pytest.mark.needs("simavr")`
(or a module's pytestmark). On a machine without it the test skips, saying what installs it.
CI sets INKSLICE_REQUIRE_TOOLS=1 (.ci/run): there a missing tool fails the test instead, so a
CI machine without chromium cannot pass by skipping every browser test.

Helpers that are plain functions live in their own modules (polling.py, *_helpers.py); the
fixtures here reach every test without an import.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REQUIRE_TOOLS = "INKSLICE_REQUIRE_TOOLS"


def _programs(*names: str) -> Callable[[], bool]:
    return lambda: all(shutil.which(n) or os.path.exists(n) for n in names)


# name in needs(...) -> (is it here?, what to install)
TOOLS: dict[str, tuple[Callable[[], bool], str]] = {
    "simavr": (_programs("avr-gcc", "simavr"), "gcc-avr and simavr (scripts/setup.sh)"),
    "systemd": (_programs("systemd-analyze"), "systemd (scripts/setup.sh --test)"),
    "chromium": (
        _programs("/usr/bin/chromium", "/usr/bin/chromedriver"),
        "Debian chromium and chromium-driver (scripts/setup.sh --test)",
    ),
    "axe-core": (
        lambda: (HERE / "a11y" / "node_modules" / "axe-core" / "axe.min.js").is_file(),
        "axe-core in tests/a11y (scripts/setup.sh --test)",
    ),
    "node": (_programs("node"), "node (scripts/setup.sh --test installs npm with it)"),
    "rs274": (_programs("/usr/bin/rs274"), "LinuxCNC's rs274 (scripts/setup.sh --test: linuxcnc-uspace)"),
    "clang-format": (_programs("clang-format"), "clang-format (scripts/setup.sh --test)"),
}


def strict() -> bool:
    """Under INKSLICE_REQUIRE_TOOLS=1 a missing tool is a failure, not a skip."""
    return os.environ.get(REQUIRE_TOOLS, "") not in ("", "0")


def require(*tools: str) -> None:
    """Skip the running test (fail it, in strict mode) unless every tool is installed.
    A name not in TOOLS is a program looked up on PATH."""
    for tool in tools:
        present, install = TOOLS.get(tool, (_programs(tool), tool))
        if present():
            continue
        why = f"needs {install}"
        if strict():
            pytest.fail(f"{why}; {REQUIRE_TOOLS} is set, so a missing tool fails the run", pytrace=False)
        pytest.skip(why)


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "needs(*tools): skips without these programs (simavr, systemd, chromium, axe-core, node, "
        f"rs274, clang-format, or a name on PATH); fails instead under {REQUIRE_TOOLS}=1",
    )


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    for mark in item.iter_markers("needs"):
        require(*mark.args)


# ---- the firmware under simavr (tests/test_fw_*.py) ----
@pytest.fixture(scope="session")
def fw_build():
    """The firmware ELF and the HIL harness, built once."""
    require("simavr")
    from appliance.sim.hil import build

    return build()


@pytest.fixture
def bench(fw_build):
    """A fresh simulated bench running flat out, stage 40 mm above the switch."""
    from appliance.sim.hil import SimulatedBench

    with SimulatedBench(speed=0) as b:
        yield b


@pytest.fixture
def link(bench):
    """The line protocol by hand (fw_helpers.RawLink) to the bench's serial port."""
    from fw_helpers import RawLink

    lk = RawLink(bench.port)
    yield lk
    lk.close()
    assert bench.stats()["rx_overruns"] == 0, "the firmware let its 2-byte receive FIFO overflow"
