"""A test that needs a program from outside Python skips on a machine without it, and fails
instead where CI says every tool must be there (INKSLICE_REQUIRE_TOOLS=1, set by .ci/run).

So a CI machine that lacks simavr, systemd or chromium cannot pass by skipping the tests that
use them. The rule lives once, in conftest.py (the `needs` marker); these tests run it on a
small suite of its own in a fresh pytest.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent

SUITE = """
import pytest

@pytest.mark.needs("inkslice-no-such-program")
def test_wants_a_program_nobody_has():
    pass

@pytest.mark.needs("sh")
def test_wants_the_shell():
    pass
"""


def run_suite(tmp_path, **env):
    (tmp_path / "conftest.py").write_text((TESTS / "conftest.py").read_text())
    (tmp_path / "test_suite.py").write_text(SUITE)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    clean = {k: v for k, v in os.environ.items() if k != "INKSLICE_REQUIRE_TOOLS"}
    r = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rsf", "-p", "no:cacheprovider", str(tmp_path)],
        cwd=tmp_path,
        env={**clean, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )
    return r.returncode, r.stdout + r.stderr


def test_without_the_variable_a_missing_program_skips_saying_what_is_missing(tmp_path):
    code, out = run_suite(tmp_path)
    assert code == 0, out
    assert "1 passed, 1 skipped" in out, out
    assert "needs inkslice-no-such-program" in out


@pytest.mark.parametrize("value", ["1", "yes"])
def test_under_inkslice_require_tools_a_missing_program_fails_the_run(tmp_path, value):
    code, out = run_suite(tmp_path, INKSLICE_REQUIRE_TOOLS=value)
    assert code != 0, out
    assert "1 passed, 1 error" in out, out  # it fails while setting the test up
    assert "needs inkslice-no-such-program" in out and "INKSLICE_REQUIRE_TOOLS is set" in out


def test_ci_requires_every_tool():
    ci = (REPO / ".ci/run").read_text()
    assert re.search(r"^export INKSLICE_REQUIRE_TOOLS=1$", ci, re.M), (
        ".ci/run must set INKSLICE_REQUIRE_TOOLS=1"
    )
    assert ci.index("INKSLICE_REQUIRE_TOOLS") < ci.index("make test")


def test_no_test_skips_on_a_missing_program_by_itself():
    """A skipif on shutil.which or a module-level skip of its own would escape the CI rule."""
    own = re.compile(r"skipif\([^)]*(which|exists)\(|pytest\.skip\([^)]*not installed")
    offenders = [p.name for p in TESTS.glob("test_*.py") if own.search(p.read_text())]
    assert not offenders, f"use @pytest.mark.needs(...) (conftest.py) in {offenders}"
