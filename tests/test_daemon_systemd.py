"""The systemd units verify without warnings, the daemon's hardening scores
4.0 or better, the udev rules and the bench wiring parse, and the install
script lays everything out."""
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from appliance.hw.devices import WIRING, load_wiring

REPO = Path(__file__).resolve().parents[1]
UNITS = ("inkslice-daemon.service", "inkslice-web.service")
pytestmark = pytest.mark.skipif(shutil.which("systemd-analyze") is None,
                                reason="systemd-analyze missing (scripts/setup.sh --test installs systemd)")


@pytest.fixture
def units(tmp_path):
    """The units as installed, with /opt/inkslice pointing at this checkout so
    verify can check that ExecStart's binary exists."""
    out = []
    for name in UNITS:
        text = (REPO / "systemd" / name).read_text().replace("/opt/inkslice", str(REPO))
        (tmp_path / name).write_text(text)
        out.append(tmp_path / name)
    assert (REPO / ".venv/bin/inkslice").exists(), "run scripts/setup.sh first"
    return out


def test_units_verify_without_warnings(units):
    r = subprocess.run(["systemd-analyze", "verify", *map(str, units)], capture_output=True, text=True,
                       cwd=units[0].parent)
    # verify only warns on stderr for a misspelt key: any output is a failure
    lines = [l for l in (r.stdout + r.stderr).splitlines() if l.strip()]
    assert r.returncode == 0 and lines == [], "\n".join(lines)


def test_a_misspelt_key_would_be_caught(units, tmp_path):
    bad = tmp_path / "bad.service"
    bad.write_text(units[0].read_text().replace("ProtectHome=yes", "ProtectHomee=yes"))
    r = subprocess.run(["systemd-analyze", "verify", str(bad)], capture_output=True, text=True)
    assert "ProtectHomee" in r.stderr


def exposure(unit):
    r = subprocess.run(["systemd-analyze", "security", "--offline=true", str(unit)],
                       capture_output=True, text=True, cwd=unit.parent)
    m = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    return float(m.group(1))


def test_the_daemon_is_hardened(units):
    daemon, web = units
    assert exposure(daemon) <= 4.0
    assert exposure(web) <= 4.0


def test_the_daemon_unit_keeps_its_promises():
    text = (REPO / "systemd/inkslice-daemon.service").read_text()
    for line in ("Type=notify", "WatchdogSec=", "Restart=on-failure", "User=inkslice", "DevicePolicy=closed",
                 "DeviceAllow=char-video4linux rw", "DeviceAllow=char-gpiochip rw", "DeviceAllow=char-i2c rw",
                 "StateDirectory=inkslice"):
        assert line in text, line
    assert "--data /var/lib/inkslice" in text


def test_udev_rules_parse():
    pair = re.compile(r'^(?P<key>[A-Z_]+(\{[^}]+\})?)(?P<op>==|!=|\+=|:=|=)"(?P<val>[^"]*)"$')
    rules = [l for l in (REPO / "systemd/99-inkslice.rules").read_text().splitlines()
             if l.strip() and not l.startswith("#")]
    assert rules
    names = set()
    for rule in rules:
        parts = [p.strip() for p in rule.split(", ")]
        for p in parts:
            assert pair.match(p), f"not a udev key/value: {p!r} in {rule!r}"
        assert any("==" in p for p in parts) and any(re.match(r"(MODE|GROUP|SYMLINK)", p) for p in parts)
        names |= set(re.findall(r'SYMLINK\+="([^"]+)"', rule))
    # the names the wiring defaults open
    assert {"inkslice-stage", "inkslice-camera"} <= names
    assert WIRING["stage_port"] == "/dev/inkslice-stage" and WIRING["camera"] == "/dev/inkslice-camera"


def test_the_example_wiring_is_valid(tmp_path):
    w = load_wiring(REPO / "systemd/bench.json")
    assert w["stage_port"] == "/dev/inkslice-stage"
    from appliance.hw.camera import CameraSettings
    CameraSettings(**w["camera_settings"])
    bad = tmp_path / "bench.json"
    bad.write_text(json.dumps({"stage_prot": "/dev/ttyACM0"}))
    with pytest.raises(Exception, match="stage_prot"):
        load_wiring(bad)


def test_install_script_lays_the_files_out(tmp_path):
    root = tmp_path / "root"
    r = subprocess.run([str(REPO / "systemd/install.sh"), "--root", str(root)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    for path in ("etc/systemd/system/inkslice-daemon.service", "etc/systemd/system/inkslice-web.service",
                 "etc/udev/rules.d/99-inkslice.rules", "etc/inkslice/bench.json",
                 "opt/inkslice/pyproject.toml", "opt/inkslice/appliance/daemon/service.py"):
        assert (root / path).is_file(), path
    assert not (root / "opt/inkslice/.git").exists()
    # a second run keeps the operator's wiring
    (root / "etc/inkslice/bench.json").write_text('{"light_line": 5}')
    subprocess.run([str(REPO / "systemd/install.sh"), "--root", str(root)], check=True, capture_output=True)
    assert json.loads((root / "etc/inkslice/bench.json").read_text()) == {"light_line": 5}
