"""USB stick detection from a fake /proc/mounts + sysfs, and the verified copy."""

import os
import subprocess
from collections import namedtuple

import pytest

from appliance.errors import DeviceError
from appliance.hw import usb


@pytest.fixture
def bench(tmp_path):
    media = tmp_path / "media"
    sysfs = tmp_path / "sys"

    def stick(name, dev, removable="1", usb_bus=False):
        m = media / "pi" / name
        m.mkdir(parents=True)
        disk = dev.rstrip("0123456789")
        real = sysfs / "devices" / ("pci0/usb1/1-1" if usb_bus else "pci0/ata1") / "block" / disk
        (real / dev).mkdir(parents=True)
        (real / "removable").write_text(removable + "\n")
        (sysfs / "class" / "block").mkdir(parents=True, exist_ok=True)
        for n, target in ((disk, real), (dev, real / dev)):
            link = sysfs / "class" / "block" / n
            if not link.exists():
                link.symlink_to(target)
        return m

    return tmp_path, media, sysfs, stick


def test_find_sticks_filters_the_mount_table(bench):
    tmp, media, sysfs, stick = bench
    a = stick("KINGSTON", "sdb1")
    b = stick("My Stick", "sdc1", removable="0", usb_bus=True)  # USB SSD: not "removable", but on USB
    c = stick("INTERNAL", "sda2", removable="0")  # a SATA disk mounted under /media
    ro = stick("READONLY", "sdd1")
    mounts = tmp / "mounts"
    esc = str(b).replace(" ", "\\040")
    mounts.write_text(
        "\n".join(
            [
                "/dev/mmcblk0p2 / ext4 rw,noatime 0 0",
                "proc /proc proc rw 0 0",
                f"/dev/sdb1 {a} vfat rw,nosuid,nodev,relatime,uid=1000 0 0",
                f"/dev/sdc1 {esc} exfat rw,relatime 0 0",
                f"/dev/sda2 {c} ext4 rw,relatime 0 0",
                f"/dev/sdd1 {ro} vfat ro,relatime 0 0",
                f"tmpfs {media}/pi/ram tmpfs rw 0 0",
                f"/dev/sde1 {tmp}/elsewhere vfat rw 0 0",
            ]
        )
        + "\n"
    )
    found = usb.find_sticks(mounts, roots=(str(media),), sys_root=sysfs)
    assert [(s.id, s.label, s.fstype) for s in found] == [
        ("sdb1", "KINGSTON", "vfat"),
        ("sdc1", "My Stick", "exfat"),
    ]
    assert found[0].free_bytes > 0
    assert usb.find_sticks(tmp / "no-such-file") == []


def test_copy_verified_writes_fsyncs_and_never_overwrites(tmp_path):
    src = tmp_path / "toolpath.gcode"
    data = b"G21 G90\nG1 X1 Y2 Z3 F800\n" * 5000
    src.write_bytes(data)
    dest = tmp_path / "stick"
    dest.mkdir()
    r1 = usb.copy_verified(src, dest, "job1-toolpath.gcode")
    r2 = usb.copy_verified(src, dest, "job1-toolpath.gcode")
    assert (r1.name, r2.name) == ("job1-toolpath.gcode", "job1-toolpath-1.gcode")
    for r in (r1, r2):
        assert (
            (dest / r.name).read_bytes() == data and r.verified and r.safe_to_remove and r.bytes == len(data)
        )
    assert sorted(os.listdir(dest)) == ["job1-toolpath-1.gcode", "job1-toolpath.gcode"]  # no temp files left
    r3 = usb.copy_verified(src, dest, "a:b*c?.gcode")
    assert r3.name == "a_b_c_.gcode"


def test_copy_refuses_when_the_stick_is_full(tmp_path, monkeypatch):
    src = tmp_path / "t.gcode"
    src.write_bytes(b"x" * 1000)
    dest = tmp_path / "stick"
    dest.mkdir()
    Usage = namedtuple("Usage", "total used free")
    monkeypatch.setattr(usb.shutil, "disk_usage", lambda p: Usage(10, 10, 1000))
    with pytest.raises(DeviceError, match="not enough space"):
        usb.copy_verified(src, dest)
    assert os.listdir(dest) == []


def test_copy_reports_a_failed_verification(tmp_path, monkeypatch):
    src = tmp_path / "t.gcode"
    src.write_bytes(b"G0 X0\n")
    dest = tmp_path / "stick"
    dest.mkdir()
    monkeypatch.setattr(usb, "_sha256", lambda p: "0" * 64)  # the stick gives back other bytes
    with pytest.raises(DeviceError, match="verification failed"):
        usb.copy_verified(src, dest)


@pytest.fixture
def one_stick(tmp_path):
    stick = tmp_path / "media" / "STICK"
    stick.mkdir(parents=True)
    mounts = tmp_path / "mounts"
    src = tmp_path / "toolpath.gcode"
    src.write_text("G21 G90\nG1 X1\n")

    def exporter(unmount):
        mounts.write_text(f"/dev/sdb1 {stick} vfat rw 0 0\n")  # plugged in (again)
        return usb.UsbExporter(
            mounts_file=mounts, roots=(str(tmp_path / "media"),), sys_root=tmp_path / "nosys", unmount=unmount
        )

    return exporter, mounts, src


def test_a_released_stick_is_safe_to_remove_only_once_it_left_the_mount_table(one_stick):
    exporter, mounts, src = one_stick
    r = exporter(lambda s: mounts.write_text("")).export(src, release=True)
    assert (r.verified, r.unmounted, r.safe_to_remove, r.unmount_problem) == (True, True, True, "")
    r = exporter(lambda s: None).export(src, release=True)  # "unmounted", yet still there
    assert (r.verified, r.unmounted, r.safe_to_remove, r.unmount_problem) == (
        True,
        False,
        False,
        "it is still mounted",
    )

    def refuses(s):
        raise DeviceError(s.mount, "udisksctl: target is busy")

    r = exporter(refuses).export(src, release=True)
    assert (r.unmounted, r.safe_to_remove, r.unmount_problem) == (False, False, "udisksctl: target is busy")


def test_an_export_without_release_leaves_the_stick_mounted(one_stick):
    """The web's export: the operator may copy several files in a row."""
    exporter, mounts, src = one_stick
    calls = []
    r = exporter(calls.append).export(src)
    assert calls == [] and r.unmounted is None and r.safe_to_remove and r.verified


def test_the_box_unmounts_its_own_sticks_through_their_unit_and_a_desktops_through_udisks(monkeypatch):
    box = usb.Stick("sdb1", "/media/inkslice/KINGSTON", "/dev/sdb1", "vfat", "KINGSTON", 1)
    desktop = usb.Stick("sdc1", "/media/pi/STICK", "/dev/sdc1", "vfat", "STICK", 1)
    monkeypatch.setattr(usb.shutil, "which", lambda name: None)
    assert usb._unmount_command(box) == ["systemctl", "stop", "inkslice-stick@sdb1.service"]
    assert usb._unmount_command(desktop) is None
    with pytest.raises(DeviceError, match="no way to unmount it here"):
        usb.unmount_stick(desktop)
    monkeypatch.setattr(usb.shutil, "which", lambda name: f"/usr/bin/{name}")
    assert usb._unmount_command(desktop) == [
        "udisksctl",
        "unmount",
        "--no-user-interaction",
        "-b",
        "/dev/sdc1",
    ]
    # a refused stop comes back as the tool's own last line
    ran = []

    def run(cmd, **kw):
        ran.append(cmd)
        return subprocess.CompletedProcess(
            cmd, 1, "", "Failed to stop inkslice-stick@sdb1.service: Access denied\n"
        )

    monkeypatch.setattr(usb.subprocess, "run", run)
    with pytest.raises(
        DeviceError, match="systemctl: Failed to stop inkslice-stick@sdb1.service: Access denied"
    ):
        usb.unmount_stick(box)
    assert ran == [["systemctl", "stop", "inkslice-stick@sdb1.service"]]
