"""The host side of the stepper controller's line protocol (appliance/firmware/stepper/PROTOCOL.md).

Pure functions and data, no serial port: framing a command, checking and
splitting a reply or a status report.  Nothing the firmware must agree with
is written here: the protocol version, the line length, the real-time bytes,
the verbs and their argument counts, and the codes (errors, states, flags,
alarms, reset reasons, settings) are read at import from
appliance/firmware/stepper/codes.def, the same X-macro table the firmware is
compiled from, so the two sides cannot drift apart (tests/test_fw_host.py
compares this module with what the C compiler made of the table).
"""

from __future__ import annotations

import binascii
import re
from dataclasses import dataclass, field
from pathlib import Path

from appliance.errors import DeviceError
from appliance.firmware import codes_path


@dataclass(frozen=True)
class Code:
    kind: str
    number: int
    name: str
    text: str


@dataclass(frozen=True)
class Verb:
    name: str
    args: int  # exactly this many arguments
    text: str


@dataclass(frozen=True)
class Setting:
    number: int
    name: str
    default: int
    low: int
    high: int
    text: str


@dataclass
class Table:
    """Everything codes.def defines, by kind."""

    constants: dict[str, int] = field(default_factory=dict)
    realtime: dict[str, bytes] = field(default_factory=dict)
    verbs: dict[str, Verb] = field(default_factory=dict)
    codes: dict[str, dict[int, Code]] = field(default_factory=dict)
    settings: dict[str, Setting] = field(default_factory=dict)


_NUM = r"(-?\d+|0x[0-9A-Fa-f]+)"
_TEXT = r'"([^"]*)"'
_CONSTANT_RE = re.compile(rf"^CONSTANT\((\w+),\s*{_NUM},\s*{_TEXT}\)\s*$")
_REALTIME_RE = re.compile(rf"^REALTIME\((\w+),\s*{_NUM},\s*{_TEXT}\)\s*$")
_VERB_RE = re.compile(rf"^VERB\((\w+),\s*(\d+),\s*{_TEXT}\)\s*$")
_CODE_RE = re.compile(rf"^CODE\((\w+),\s*(\d+),\s*(\w+),\s*{_TEXT}\)\s*$")
_SETTING_RE = re.compile(rf"^SETTING\((\d+),\s*(\w+),\s*{_NUM},\s*{_NUM},\s*{_NUM},\s*{_TEXT}\)\s*$")
_NEEDED = {
    "constants": ("PROTO_VERSION", "LINE_MAX"),
    "realtime": ("RT_STATUS", "RT_ESTOP"),
    "codes": ("ERR", "STATE", "FLAG", "ALARM", "RESET"),
}


def _read_entry(line: str, table: Table) -> None:
    if m := _CONSTANT_RE.match(line):
        table.constants[m[1]] = int(m[2], 0)
    elif m := _REALTIME_RE.match(line):
        table.realtime[m[1]] = bytes([int(m[2], 0)])
    elif m := _VERB_RE.match(line):
        table.verbs[m[1]] = Verb(m[1], int(m[2]), m[3])
    elif m := _CODE_RE.match(line):
        c = Code(m[1], int(m[2]), m[3], m[4])
        table.codes.setdefault(c.kind, {})[c.number] = c
    elif m := _SETTING_RE.match(line):
        s = Setting(int(m[1]), m[2], int(m[3], 0), int(m[4], 0), int(m[5], 0), m[6])
        table.settings[s.name] = s


def load_table(path: Path | None = None) -> Table:
    path = path or codes_path()
    try:
        text = path.read_text()
    except OSError as e:
        raise DeviceError(path, f"cannot read the protocol table: {e.strerror}") from None
    table = Table()
    for line in text.splitlines():
        _read_entry(line, table)
    for kind, names in _NEEDED.items():
        missing = [n for n in names if n not in getattr(table, kind)]
        if missing:
            raise DeviceError(path, f"the protocol table defines no {', '.join(missing)}")
    if not table.verbs:
        raise DeviceError(path, "the protocol table defines no verbs")
    return table


TABLE = load_table()
PROTO_VERSION = TABLE.constants["PROTO_VERSION"]
LINE_MAX = TABLE.constants["LINE_MAX"]  # characters the firmware buffers before '\n'
RT_STATUS = TABLE.realtime["RT_STATUS"]  # real-time: status report
RT_ESTOP = TABLE.realtime["RT_ESTOP"]  # real-time: emergency stop (Ctrl-X)
VERBS = TABLE.verbs
CODES, SETTINGS = TABLE.codes, TABLE.settings
ERRORS = CODES["ERR"]
STATES = CODES["STATE"]
ALARMS = CODES["ALARM"]
ALARMS_BY_NAME = {c.name: c for c in ALARMS.values()}
FLAG_BITS = {c.name: c.number for c in CODES["FLAG"].values()}
ERROR_NUMBER = {c.name: c.number for c in ERRORS.values()}


class ProtocolError(Exception):
    """A line from the controller that is damaged or not in the protocol."""


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE, the firmware's crc16()."""
    return binascii.crc_hqx(data, 0xFFFF)


def seal(body: str) -> bytes:
    return f"{body}*{crc16(body.encode('ascii')):04X}".encode("ascii")


def encode_command(seq: int, verb: str, *args, check: bool = True) -> bytes:
    """The bytes to send for one command.  The leading '\\n' ends whatever
    junk a damaged earlier line left in the firmware's line buffer.  A verb
    the table does not know, or the wrong number of arguments, is refused
    unless check is False (tests that send the firmware what it must reject)."""
    if not 1 <= seq <= 65535:
        raise ValueError(f"sequence number {seq} outside 1..65535")
    if check and verb not in VERBS:
        raise ValueError(f"'{verb}' is not a verb of the protocol ({', '.join(VERBS)})")
    if check and len(args) != VERBS[verb].args:
        raise ValueError(f"{verb} takes {VERBS[verb].args} argument(s), not {len(args)}")
    body = " ".join([str(seq), verb, *map(str, args)])
    line = seal(body)
    if len(line) > LINE_MAX:
        raise ValueError(f"command '{body}' is {len(line)} characters; the firmware takes {LINE_MAX}")
    return b"\n" + line + b"\n"


def unseal(line: bytes) -> str:
    """The text of a received line after checking its CRC."""
    line = line.rstrip(b"\r\n")
    if len(line) < 6 or line[-5:-4] != b"*":
        raise ProtocolError(f"no checksum in {line!r}")
    try:
        body = line[:-5].decode("ascii")
        want = int(line[-4:], 16)
    except (UnicodeDecodeError, ValueError):
        raise ProtocolError(f"unreadable line {line!r}") from None
    if crc16(line[:-5]) != want:
        raise ProtocolError(f"checksum mismatch in {line!r}")
    return body


@dataclass
class Reply:
    seq: int
    ok: bool
    error: int = 0
    payload: str = ""

    @property
    def error_name(self) -> str:
        c = ERRORS.get(self.error)
        return c.name if c else f"code {self.error}"

    @property
    def error_text(self) -> str:
        c = ERRORS.get(self.error)
        return c.text if c else "an error code this driver does not know"


@dataclass
class Status:
    state: str
    position: int
    flags: dict = field(default_factory=dict)
    alarm: str = "none"

    @property
    def homed(self) -> bool:
        return self.flags.get("homed", False)


@dataclass
class Banner:
    text: str
    reset: str


def _parse_status_fields(fields: list[str]) -> Status:
    if len(fields) != 4:
        raise ProtocolError(f"status wants 4 fields, got {fields}")
    state, pos, flags, alarm = fields
    names = {c.name for c in STATES.values()}
    if state not in names:
        raise ProtocolError(f"unknown state {state!r}")
    try:
        bits = int(flags, 16)
        alarm_no = int(alarm)
        position = int(pos)
    except ValueError:
        raise ProtocolError(f"bad status fields {fields}") from None
    flag_map = {name: bool(bits >> bit & 1) for name, bit in FLAG_BITS.items()}
    a = ALARMS.get(alarm_no)
    return Status(state, position, flag_map, a.name if a else f"alarm {alarm_no}")


def parse_status_fields(text: str) -> Status:
    return _parse_status_fields(text.split())


def parse_line(line: bytes) -> Reply | Status | Banner:
    """One line from the controller: a reply, a real-time status report or the boot banner."""
    body = unseal(line)
    if body.startswith("<") and body.endswith(">"):
        return _parse_status_fields(body[1:-1].split())
    if body.startswith("#"):
        m = re.search(r"reset=(\w+)", body)
        return Banner(body, m[1] if m else "unknown")
    head, _, rest = body.partition(" ")
    try:
        seq = int(head)
    except ValueError:
        raise ProtocolError(f"reply without a sequence number: {body!r}") from None
    word, _, payload = rest.partition(" ")
    if word == "ok":
        return Reply(seq, True, 0, payload)
    if word.startswith("error:"):
        try:
            return Reply(seq, False, int(word[6:]), payload)
        except ValueError:
            pass
    raise ProtocolError(f"reply is neither ok nor error:<code>: {body!r}")


def parse_identity(payload: str) -> dict:
    """'inkslice-stepper proto=1 fw=0.1.0 reset=... settings=...' -> dict."""
    parts = payload.split()
    info = {"name": parts[0] if parts else ""}
    for p in parts[1:]:
        k, _, v = p.partition("=")
        info[k] = v
    if "proto" in info:
        try:
            info["proto"] = int(info["proto"])
        except ValueError:
            pass
    return info
