"""The firmware's pure C sources on the host: cmocka unit tests, size budget,
and the one code table both sides read."""

import re
import subprocess

from fw_helpers import BUILD, FIRMWARE_DIR, make

from appliance.hw import protocol as P


def test_host_unit_tests_of_planner_protocol_crc_and_settings_pass():
    make(str(BUILD / "test_host"))
    r = subprocess.run([str(BUILD / "test_host")], capture_output=True, text=True)
    out = r.stdout + r.stderr
    print(out)
    m = re.search(r"\[  PASSED  \] (\d+) test", out)
    assert r.returncode == 0, out
    assert m and int(m.group(1)) >= 19, out
    assert "FAILED" not in out
    print(f"host unit tests passed: {m.group(1)}")


def test_firmware_uses_at_most_half_of_flash_and_ram():
    make("firmware")
    out = subprocess.run(
        ["avr-size", "-C", "--mcu=atmega328p", str(BUILD / "inkslice-stepper.elf")],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    flash = float(re.search(r"Program:.*\(([\d.]+)% Full\)", out).group(1))
    ram = float(re.search(r"Data:.*\(([\d.]+)% Full\)", out).group(1))
    print(out)
    assert flash <= 50.0 and ram <= 50.0


def test_the_build_is_warning_free():
    """-Wall -Wextra -Werror is in the Makefile; a rebuild from scratch must pass it."""
    r = make("-B", "firmware")
    assert "warning" not in (r.stdout + r.stderr).lower()


def test_code_table_numbers_are_unique_per_kind_and_cover_the_protocol():
    for kind, codes in P.CODES.items():
        names = [c.name for c in codes.values()]
        assert len(names) == len(set(names)), kind
    text = (FIRMWARE_DIR / "codes.def").read_text()
    lines = [l for l in text.splitlines() if l.startswith("CODE(")]
    assert len(lines) == sum(len(c) for c in P.CODES.values())  # no line the regex missed
    assert {"bad_checksum", "not_homed", "soft_limit", "busy"} <= set(P.ERROR_NUMBER)
    assert {"idle", "moving", "homing", "alarm", "estop"} == {c.name for c in P.STATES.values()}
    assert P.SETTINGS["steps_per_rev"].default * 1000 / P.SETTINGS["lead_um"].default == 1600


def test_protocol_md_documents_every_error_code():
    doc = (FIRMWARE_DIR / "PROTOCOL.md").read_text()
    for c in P.ERRORS.values():
        assert c.name in doc, f"PROTOCOL.md does not mention error {c.name}"
