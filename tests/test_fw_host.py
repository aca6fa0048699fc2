"""The firmware's pure C sources on the host: cmocka unit tests, size budget,
and the one code table both sides read."""

import re
import subprocess
from pathlib import Path

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
    entries = [l for l in text.splitlines() if re.match(r"(CONSTANT|REALTIME|VERB|CODE|SETTING)\(", l)]
    t = P.TABLE
    read = len(t.constants) + len(t.realtime) + len(t.verbs) + len(t.settings)
    assert len(entries) == read + sum(len(c) for c in P.CODES.values())  # no line the regexes missed
    assert {"bad_checksum", "not_homed", "soft_limit", "busy"} <= set(P.ERROR_NUMBER)
    assert {"idle", "moving", "homing", "alarm", "estop"} == {c.name for c in P.STATES.values()}
    assert P.SETTINGS["steps_per_rev"].default * 1000 / P.SETTINGS["lead_um"].default == 1600


def test_the_firmware_compiles_the_protocol_table_the_driver_reads():
    """The constants, real-time bytes and verbs as the C compiler saw them (test/proto_table.c
    prints them from the firmware's headers and the parser's own verb table) equal the driver's."""
    make(str(BUILD / "proto_table"))
    out = subprocess.run([str(BUILD / "proto_table")], capture_output=True, text=True, check=True).stdout
    rows = [line.split() for line in out.splitlines()]
    c_constants = {name: int(v) for kind, name, v in (r for r in rows if r[0] == "CONSTANT")}
    c_realtime = {name: bytes([int(v)]) for kind, name, v in (r for r in rows if r[0] == "REALTIME")}
    c_verbs = [(name, int(args), int(err)) for kind, name, args, err in (r for r in rows if r[0] == "VERB")]
    assert c_constants == {"PROTO_VERSION": P.PROTO_VERSION, "LINE_MAX": P.LINE_MAX}
    assert c_realtime == {"RT_STATUS": P.RT_STATUS, "RT_ESTOP": P.RT_ESTOP}
    assert [(v.name, v.args, 0) for v in P.VERBS.values()] == c_verbs  # same order; C parses each


def test_no_source_spells_the_protocol_table_by_hand():
    """Neither side may define a table name again: a second definition is how they drift."""
    names = [*P.TABLE.constants, *P.TABLE.realtime]
    c_define = re.compile(rf"#\s*define\s+({'|'.join(names)})\b")
    c_verb = re.compile(rf'"({"|".join(P.VERBS)})"')
    for src in sorted((FIRMWARE_DIR / "src").glob("*.[ch]")):
        text = src.read_text()
        assert not c_define.search(text), f"{src.name} defines a constant of codes.def"
        assert not c_verb.search(text), f"{src.name} spells a verb of codes.def"
    py_assign = re.compile(rf"^\s*({'|'.join(names)})\s*=\s*(b?['\"]|\d)", re.M)
    for src in sorted(Path(P.__file__).parents[1].rglob("*.py")):  # appliance/
        assert not py_assign.search(src.read_text()), f"{src} sets a constant of codes.def by hand"


def test_protocol_md_documents_every_error_code():
    doc = (FIRMWARE_DIR / "PROTOCOL.md").read_text()
    for c in P.ERRORS.values():
        assert c.name in doc, f"PROTOCOL.md does not mention error {c.name}"
