"""Pinned installs: every Python package comes from the lock files, at one version, hash-checked.

pyproject.toml gives ranges (what the code supports); requirements.lock (the box) and
requirements-test.lock (setup for the tests, CI) pin each package to the version the tests
ran with, with the hashes of its files on PyPI. `make lock` (scripts/lock.sh) refreshes them.
So a box set up next year installs what was tested, not what PyPI offers that day.
"""

from __future__ import annotations

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

REPO = Path(__file__).resolve().parents[1]
RUN_LOCK = REPO / "requirements.lock"
TEST_LOCK = REPO / "requirements-test.lock"
# Where a package gets installed, and which lock each installer must use.
INSTALLERS = {
    "scripts/setup.sh": ("requirements.lock", "requirements-test.lock"),
    "systemd/install.sh": ("requirements.lock",),
}


def read_lock(path: Path) -> dict[str, tuple[str, list[str]]]:
    """{canonical name: (version, [sha256 hashes])} from a pip-compile lock file."""
    entries = {}
    text = re.sub(r"\\\n\s*", " ", path.read_text())  # join continuation lines
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        m = re.fullmatch(r"([A-Za-z0-9._-]+)==(\S+)((?:\s+--hash=sha256:[0-9a-f]{64})*)\s*", line)
        assert m, f"{path.name}: not a pinned, hashed requirement: {line[:80]}"
        entries[canonicalize_name(m[1])] = (m[2], re.findall(r"sha256:([0-9a-f]{64})", m[3]))
    return entries


def project() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]


def test_every_locked_package_has_one_version_and_the_hashes_of_its_files():
    for lock in (RUN_LOCK, TEST_LOCK):
        entries = read_lock(lock)
        assert entries, f"{lock.name} is empty"
        for name, (version, hashes) in entries.items():
            assert hashes, f"{lock.name}: {name}=={version} has no hash: pip --require-hashes would refuse it"


@pytest.mark.parametrize("lock, extras", [(RUN_LOCK, ()), (TEST_LOCK, ("test",))])
def test_the_lock_pins_every_dependency_inside_pyproject_s_range(lock, extras):
    entries = read_lock(lock)
    wanted = [Requirement(r) for r in project()["dependencies"]]
    wanted += [Requirement(r) for e in extras for r in project()["optional-dependencies"][e]]
    for req in wanted:
        if req.marker is not None and not req.marker.evaluate():
            continue
        name = canonicalize_name(req.name)
        assert name in entries, f"{lock.name} does not pin {req.name}: run `make lock`"
        assert req.specifier.contains(entries[name][0], prereleases=True), (
            f"{lock.name} pins {req.name}=={entries[name][0]}, outside pyproject.toml's {req}: run `make lock`"
        )


def test_the_box_s_lock_is_the_test_lock_without_the_test_tools():
    run, test = read_lock(RUN_LOCK), read_lock(TEST_LOCK)
    assert set(run) <= set(test)
    assert {n: run[n][0] for n in run} == {n: test[n][0] for n in run}, (
        "the box would run other versions than the tests"
    )
    tools = {canonicalize_name(Requirement(r).name) for r in project()["optional-dependencies"]["test"]}
    assert not tools & set(run), "the box's lock holds test tools"


def test_the_tests_run_on_the_locked_versions():
    """The venv running this suite was installed from the test lock (setup.sh --test)."""
    drift = {}
    for name, (version, _) in read_lock(TEST_LOCK).items():
        try:
            have = metadata.version(name)
        except metadata.PackageNotFoundError:
            have = None
        if have != version:
            drift[name] = (have, version)
    assert not drift, f"installed vs locked: {drift}; run scripts/setup.sh --test"


@pytest.mark.parametrize("script", sorted(INSTALLERS))
def test_installers_take_packages_only_from_the_lock(script):
    """Every `pip install` either installs a lock with --require-hashes or the package itself
    with --no-deps: nothing resolves a dependency from an open range."""
    text = (REPO / script).read_text()
    installs = [
        line.strip()
        for line in text.splitlines()
        if re.search(r"\bpip install\b", line) and not line.lstrip().startswith("#")
    ]
    assert installs, f"{script} installs nothing?"
    from_lock = [line for line in installs if "--require-hashes -r" in line]
    assert from_lock, f"{script} installs no lock file"
    for line in installs:
        if "--upgrade pip" in line:
            continue  # pip itself, before anything else
        assert line in from_lock or "--no-deps" in line, (
            f"{script}: resolves dependencies outside the lock: {line}"
        )
    for lock in INSTALLERS[script]:
        assert re.search(rf"(^|[\s/=\"']){re.escape(lock)}\b", text, re.M), f"{script} never names {lock}"


def test_ci_runs_the_quick_start_s_setup():
    """CI is `make test`, whose setup step is scripts/setup.sh --test (the test lock)."""
    assert re.search(r"^make test$", (REPO / ".ci/run").read_text(), re.M)
    makefile = (REPO / "Makefile").read_text()
    assert re.search(r"^test: setup-test$", makefile, re.M)
    assert re.search(r"^setup-test:\n\t@?scripts/setup\.sh --test$", makefile, re.M)
    assert re.search(r"^lock:\n\tscripts/lock\.sh$", makefile, re.M)
