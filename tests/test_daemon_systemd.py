"""The systemd units verify without warnings, the daemon's hardening scores
4.0 or better, the udev rules and the bench wiring parse, USB sticks get
mounted for the inkslice user and unmounted on its request, and the install
script lays everything out."""

import json
import re
import subprocess
from pathlib import Path

import pytest

from appliance.hw.devices import WIRING, load_wiring

REPO = Path(__file__).resolve().parents[1]
UNITS = ("inkslice-daemon.service", "inkslice-web.service")
pytestmark = pytest.mark.needs("systemd")


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
    r = subprocess.run(
        ["systemd-analyze", "verify", *map(str, units)], capture_output=True, text=True, cwd=units[0].parent
    )
    # verify only warns on stderr for a misspelt key: any output is a failure
    lines = [l for l in (r.stdout + r.stderr).splitlines() if l.strip()]
    assert r.returncode == 0 and lines == [], "\n".join(lines)


def test_a_misspelt_key_would_be_caught(units, tmp_path):
    bad = tmp_path / "bad.service"
    bad.write_text(units[0].read_text().replace("ProtectHome=yes", "ProtectHomee=yes"))
    r = subprocess.run(["systemd-analyze", "verify", str(bad)], capture_output=True, text=True)
    assert "ProtectHomee" in r.stderr


def exposure(unit):
    r = subprocess.run(
        ["systemd-analyze", "security", "--offline=true", str(unit)],
        capture_output=True,
        text=True,
        cwd=unit.parent,
    )
    m = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    return float(m.group(1))


def test_the_daemon_is_hardened(units):
    daemon, web = units
    assert exposure(daemon) <= 4.0
    assert exposure(web) <= 4.0


def test_the_daemon_unit_keeps_its_promises():
    text = (REPO / "systemd/inkslice-daemon.service").read_text()
    for line in (
        "Type=notify",
        "WatchdogSec=",
        "Restart=on-failure",
        "User=inkslice",
        "DevicePolicy=closed",
        "DeviceAllow=char-video4linux rw",
        "DeviceAllow=char-gpiochip rw",
        "DeviceAllow=char-i2c rw",
        "StateDirectory=inkslice",
    ):
        assert line in text, line
    assert "--data /var/lib/inkslice" in text


UDEV_PAIR = re.compile(r'^(?P<key>[A-Z_]+(\{[^}]+\})?)(?P<op>==|!=|\+=|:=|=)"(?P<val>[^"]*)"$')


def udev_rules(name):
    """Each rule of a rules file as a list of (key, operator, value); fails on anything else."""
    rules = []
    for line in (REPO / "systemd" / name).read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        parts = []
        for p in (p.strip() for p in line.split(", ")):
            m = UDEV_PAIR.match(p)
            assert m, f"not a udev key/value: {p!r} in {line!r}"
            parts.append((m["key"], m["op"], m["val"]))
        rules.append(parts)
    assert rules
    return rules


def test_udev_rules_parse():
    rules = udev_rules("99-inkslice.rules")
    names = set()
    for rule in rules:
        assert any(op == "==" for _, op, _ in rule) and any(
            k in ("MODE", "GROUP", "SYMLINK") for k, _, _ in rule
        )
        names |= {v for k, op, v in rule if k == "SYMLINK" and op == "+="}
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


# ---- USB sticks: udev rule -> inkslice-stick@DEV.service -> the mount script; polkit lets the daemon unmount

MATCH_OPS, ASSIGN_OPS = {"==", "!="}, {"=", "+=", ":="}
MATCH_KEYS = {"ACTION", "SUBSYSTEM", "KERNEL", "ENV{ID_BUS}", "ENV{ID_FS_USAGE}", "ENV{ID_FS_TYPE}"}
ASSIGN_KEYS = {"TAG", "ENV{SYSTEMD_WANTS}", "ENV{UDISKS_IGNORE}"}


def test_the_stick_rule_asks_systemd_for_the_mount_unit_of_usb_fat_and_exfat_sticks():
    (rule,) = udev_rules("99-inkslice-usb.rules")
    for key, op, _ in rule:
        assert (key in MATCH_KEYS and op in MATCH_OPS) or (key in ASSIGN_KEYS and op in ASSIGN_OPS), (key, op)
    match = {k: v for k, op, v in rule if op == "=="}
    assert match["ACTION"] == "add" and match["SUBSYSTEM"] == "block" and match["ENV{ID_BUS}"] == "usb"
    assert match["ENV{ID_FS_USAGE}"] == "filesystem"
    assert set(match["ENV{ID_FS_TYPE}"].split("|")) == {"vfat", "exfat"}  # what the mount script mounts
    assign = {(k, op): v for k, op, v in rule if op in ASSIGN_OPS}
    assert assign[("TAG", "+=")] == "systemd", "without the systemd tag SYSTEMD_WANTS is ignored"
    unit = assign[("ENV{SYSTEMD_WANTS}", "+=")]
    assert unit == "inkslice-stick@%k.service" and (REPO / "systemd" / "inkslice-stick@.service").is_file()
    assert not any(k == "RUN" for k, _, _ in rule), "udev must not mount: its namespace would hide the mount"


def test_the_stick_unit_verifies_without_warnings(tmp_path):
    text = (REPO / "systemd/inkslice-stick@.service").read_text()
    assert "ExecStart=/usr/local/lib/inkslice/inkslice-stick mount %I" in text
    assert (
        "ExecStop=/usr/local/lib/inkslice/inkslice-stick unmount %I" in text
        and "BindsTo=dev-%i.device" in text
    )
    unit = tmp_path / "inkslice-stick@sdb1.service"  # a template verifies as one of its instances
    unit.write_text(
        text.replace("/usr/local/lib/inkslice/inkslice-stick", str(REPO / "systemd/inkslice-stick"))
    )
    r = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, cwd=tmp_path)
    lines = [l for l in (r.stdout + r.stderr).splitlines() if l.strip()]
    assert r.returncode == 0 and lines == [], "\n".join(lines)


@pytest.fixture
def stick_tools(tmp_path):
    """The mount script with blkid, id, mount & co. stood in for by scripts that log their arguments."""
    log = tmp_path / "calls"
    tools = tmp_path / "bin"
    tools.mkdir()
    fakes = {
        "blkid": 'case "$*" in *TYPE*) echo "${FAKE_TYPE}";; *LABEL*) printf "%s\\n" "${FAKE_LABEL}";; esac',
        "id": 'case "$1" in -u) echo 990;; -g) echo 980;; esac',
        "mountpoint": '[ -e "$2/.mounted" ]',
        "mount": 'echo "mount $*" >> "$LOG"; case "$6" in "$INKSLICE_STICK_ROOT"/*) touch "$6/.mounted";; esac',
        "findmnt": 'echo "$FAKE_MNT"',
        "sync": 'echo "sync $*" >> "$LOG"',
        "umount": 'echo "umount $*" >> "$LOG"; rm -f "$1/.mounted"',
    }
    for name, body in fakes.items():
        (tools / name).write_text(f"#!/bin/sh\n{body}\n")
        (tools / name).chmod(0o755)
    root = tmp_path / "media" / "inkslice"

    def run(*args, **env):
        e = {
            "PATH": f"{tools}:/usr/bin:/bin",
            "LOG": str(log),
            "INKSLICE_STICK_ROOT": str(root),
            "FAKE_TYPE": "vfat",
            "FAKE_LABEL": "",
            "FAKE_MNT": "",
            **env,
        }
        r = subprocess.run(
            ["sh", str(REPO / "systemd/inkslice-stick"), *args], env=e, capture_output=True, text=True
        )
        calls = log.read_text().splitlines() if log.exists() else []
        log.unlink(missing_ok=True)
        return r, calls

    return run, root


def test_a_stick_is_mounted_for_the_inkslice_user_under_its_label(stick_tools):
    run, root = stick_tools
    r, calls = run("mount", "sdb1", FAKE_TYPE="vfat", FAKE_LABEL="MY STICK")
    assert r.returncode == 0, r.stderr
    (call,) = calls
    assert call.startswith(
        "mount -t vfat -o rw,nosuid,nodev,noexec,noatime,uid=990,gid=980,fmask=0117,dmask=0007"
    )
    assert ",flush," in call and call.endswith(f"/dev/sdb1 {root}/MY_STICK")
    # a second stick with the same label gets its own folder; exFAT gets owner options too (no flush)
    r, (call,) = run("mount", "sdc1", FAKE_TYPE="exfat", FAKE_LABEL="MY STICK")
    assert (
        "uid=990,gid=980" in call and "flush" not in call and call.endswith(f"/dev/sdc1 {root}/MY_STICK-sdc1")
    )
    # no label: the kernel's name
    r, (call,) = run("mount", "sdd1", FAKE_TYPE="vfat", FAKE_LABEL="")
    assert call.endswith(f"{root}/sdd1")


def test_the_mount_script_refuses_what_is_not_a_stick_file_system(stick_tools):
    run, _ = stick_tools
    r, calls = run("mount", "sdb1", FAKE_TYPE="ext4")
    assert r.returncode == 1 and calls == []
    assert "holds ext4, not a stick file system the box mounts (vfat, exfat)" in r.stderr
    r, calls = run("eject", "sdb1")
    assert r.returncode == 2 and "usage" in r.stderr


def test_unmount_syncs_first_and_removes_the_mount_point(stick_tools):
    run, root = stick_tools
    run("mount", "sdb1", FAKE_TYPE="vfat", FAKE_LABEL="KINGSTON")
    mnt = root / "KINGSTON"
    assert mnt.is_dir()
    r, calls = run("unmount", "sdb1", FAKE_MNT=str(mnt))
    assert r.returncode == 0, r.stderr
    assert calls == [f"sync -f {mnt}", f"umount {mnt}"] and not mnt.exists()
    assert "safe to remove" in r.stdout
    r, calls = run("unmount", "sdb1", FAKE_MNT="")  # already gone: nothing to do
    assert r.returncode == 0 and calls == []


@pytest.mark.needs("node")  # it runs the polkit rule (JavaScript)
def test_the_polkit_rule_lets_the_inkslice_user_stop_stick_units_and_nothing_else():
    from appliance.hw.usb import Stick, _unmount_command

    cmd = _unmount_command(
        Stick("sdb1", "/media/inkslice/KINGSTON", "/dev/sdb1", "vfat", "KINGSTON", 1 << 30)
    )
    assert cmd[:2] == ["systemctl", "stop"]
    cases = [
        ("inkslice", "stop", cmd[2], True),  # what hw/usb.py asks for
        ("inkslice", "start", cmd[2], False),
        ("inkslice", "stop", "inkslice-daemon.service", False),
        ("inkslice", "stop", "inkslice-stick@../x.service", False),
        ("pi", "stop", cmd[2], False),
    ]
    script = """
        const fs = require("fs"); const rules = [];
        const polkit = {addRule: f => rules.push(f), Result: {YES: "yes", NO: "no"}};
        new Function("polkit", fs.readFileSync(process.argv[1], "utf8"))(polkit);
        const out = JSON.parse(process.argv[2]).map(([user, verb, unit]) => rules.some(r => r(
            {id: "org.freedesktop.systemd1.manage-units", lookup: k => ({verb, unit})[k]}, {user}) === "yes"));
        console.log(JSON.stringify(out));"""
    r = subprocess.run(
        [
            "node",
            "-e",
            script,
            str(REPO / "systemd/50-inkslice-stick.rules"),
            json.dumps([c[:3] for c in cases]),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == [c[3] for c in cases]


def test_install_script_lays_the_files_out(tmp_path):
    root = tmp_path / "root"
    r = subprocess.run(
        [str(REPO / "systemd/install.sh"), "--root", str(root)], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    for path in (
        "etc/systemd/system/inkslice-daemon.service",
        "etc/systemd/system/inkslice-web.service",
        "etc/udev/rules.d/99-inkslice.rules",
        "etc/inkslice/bench.json",
        "etc/udev/rules.d/99-inkslice-usb.rules",
        "etc/systemd/system/inkslice-stick@.service",
        "usr/local/lib/inkslice/inkslice-stick",
        "etc/polkit-1/rules.d/50-inkslice-stick.rules",
        "opt/inkslice/pyproject.toml",
        "opt/inkslice/requirements.lock",
        "opt/inkslice/appliance/daemon/service.py",
    ):
        assert (root / path).is_file(), path
    assert not (root / "opt/inkslice/.git").exists()
    assert (root / "usr/local/lib/inkslice/inkslice-stick").stat().st_mode & 0o111, "the mount script runs"
    # a second run keeps the operator's wiring
    (root / "etc/inkslice/bench.json").write_text('{"light_line": 5}')
    subprocess.run([str(REPO / "systemd/install.sh"), "--root", str(root)], check=True, capture_output=True)
    assert json.loads((root / "etc/inkslice/bench.json").read_text()) == {"light_line": 5}
