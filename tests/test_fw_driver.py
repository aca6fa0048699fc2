"""The Python side of the protocol, without simavr: framing, parsing, and the
driver against a scripted fake controller on a pty (identify refusal,
timeouts, resend on a damaged reply)."""

import os
import threading
import time
import tty

import pytest

from appliance.errors import DeviceError, SettingError
from appliance.hw import protocol as P
from appliance.hw.stage import SerialStage


def test_crc_is_the_firmware_crc16_ccitt_false():
    assert P.crc16(b"123456789") == 0x29B1


def test_a_command_is_framed_with_a_leading_newline_and_its_crc():
    assert P.encode_command(1, "ID") == b"\n1 ID*E74F\n"
    with pytest.raises(ValueError):
        P.encode_command(0, "ID")
    with pytest.raises(ValueError, match="48"):
        P.encode_command(1, "SET", "x" * 40, 1)


def test_the_driver_refuses_a_verb_or_an_argument_count_the_table_does_not_know():
    with pytest.raises(ValueError, match="not a verb"):
        P.encode_command(1, "JUMP")
    with pytest.raises(ValueError, match="MOVE takes 1"):
        P.encode_command(1, "MOVE")
    assert P.encode_command(1, "JUMP", check=False).endswith(b"\n")  # for tests of the firmware's refusal


def test_a_protocol_table_without_its_constants_is_refused_not_half_read(tmp_path):
    table = (P.codes_path()).read_text()
    damaged = tmp_path / "codes.def"
    damaged.write_text("\n".join(l for l in table.splitlines() if not l.startswith("CONSTANT(LINE_MAX")))
    with pytest.raises(DeviceError, match="defines no LINE_MAX"):
        P.load_table(damaged)
    assert P.load_table(P.codes_path()).constants["LINE_MAX"] == P.LINE_MAX


def test_replies_status_reports_and_banners_parse():
    r = P.parse_line(P.seal("17 error:7") + b"\n")
    assert (r.seq, r.ok, r.error_name) == (17, False, "soft_limit")
    st = P.parse_line(P.seal("<moving -120 03 0>") + b"\n")
    assert (st.state, st.position, st.homed, st.flags["limit_bottom"]) == ("moving", -120, True, True)
    b = P.parse_line(P.seal("# inkslice-stepper proto=1 reset=watchdog") + b"\n")
    assert b.reset == "watchdog"
    with pytest.raises(P.ProtocolError, match="checksum"):
        P.parse_line(b"17 ok*0000\n")
    with pytest.raises(P.ProtocolError):
        P.parse_line(P.seal("<flying 1 00 0>") + b"\n")


class FakeController:
    """A pty whose far end answers like firmware, as scripted by `answer(body) -> list[bytes]`."""

    def __init__(self, answer):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.answer = answer
        self.lines = []
        self._stop = False
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self):
        buf = b""
        while not self._stop:
            try:
                data = os.read(self.master, 256)
            except OSError:
                return
            buf += data
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                if not line:
                    continue
                self.lines.append(line)
                for out in self.answer(P.unseal(line)):
                    os.write(self.master, out)

    def close(self):
        self._stop = True
        os.close(self.slave)
        os.close(self.master)


def firmware(proto=1, damage_first=0):
    state = {"damaged": 0}

    def answer(body):
        seq, verb, *args = body.split()
        if verb == "ID":
            text = f"{seq} ok inkslice-stepper proto={proto} fw=9.9 reset=power_on settings=ok"
        elif verb == "GET":
            text = f"{seq} ok {P.SETTINGS[args[0]].default}"
        else:
            text = f"{seq} error:4"
        line = P.seal(text) + b"\n"
        if state["damaged"] < damage_first:
            state["damaged"] += 1
            line = line[:3] + b"X" + line[4:]
        return [line]

    return answer


def test_a_firmware_speaking_another_protocol_version_is_refused_by_name():
    fake = FakeController(firmware(proto=2))
    try:
        with pytest.raises(DeviceError, match="protocol 2 but this driver speaks protocol 1"):
            SerialStage(fake.port)
    finally:
        fake.close()


def test_a_silent_device_fails_within_the_timeout_with_a_clear_message():
    fake = FakeController(lambda body: [])
    try:
        t = time.monotonic()
        with pytest.raises(DeviceError, match="no reply to ID"):
            SerialStage(fake.port, timeout=0.8)
        assert time.monotonic() - t < 0.8 + 2.0  # its timeout, plus slack for a loaded machine
        assert len(fake.lines) >= 3 and len(set(fake.lines)) == 1  # the same line, resent
    finally:
        fake.close()


def test_a_damaged_reply_makes_the_driver_resend_the_same_line():
    fake = FakeController(firmware(damage_first=2))
    try:
        stage = SerialStage(fake.port)
        assert stage.info["proto"] == 1 and stage.steps_per_mm == 1600
        assert stage.counters["resends"] == 2 and stage.counters["damaged_lines"] == 2
        assert fake.lines[0] == fake.lines[1] == fake.lines[2]
        with pytest.raises(SettingError, match="outside 1..20"):
            stage.set_setting("pulse_us", 0)
        stage.close()
    finally:
        fake.close()


def test_a_damaged_reply_is_resent_at_once_not_waited_out_as_silence():
    """Noise, not slowness: the link answered within milliseconds, the answer was hit. Waiting
    out each damaged reply (and growing the wait as for a slow link) cost a soak run's status
    polls most of their budget."""
    fake = FakeController(firmware(damage_first=3))
    try:
        t = time.monotonic()
        stage = SerialStage(fake.port, reply_timeout=0.5)
        took = time.monotonic() - t
        assert stage.counters["damaged_lines"] == 3 and stage.counters["resends"] == 3
        assert took < 0.5  # waited out, the three would have taken 0.5 + 0.75 + 1.1 s
        assert stage.rtt.wait() == stage.reply_timeout  # and the wait did not grow
        stage.close()
    finally:
        fake.close()


def test_on_a_link_that_slows_down_the_driver_waits_as_long_as_the_measured_round_trip_needs():
    """The replies slow from 10 ms to 1.5 s, past the driver's 1 s timeout (a loaded host, a
    congested hub). A fixed wait would give up; this one has measured the round trips on the way
    and gives each command the time the link needs, resending little."""
    delay = [0.01]
    script = firmware()

    def answer(body):
        for line in script(body):
            threading.Timer(delay[0], lambda out=line: os.write(fake.master, out)).start()
        return []

    fake = FakeController(answer)
    stage = SerialStage(fake.port, timeout=1.0, reply_timeout=0.05)
    try:
        while delay[0] < 1.5:
            delay[0] = min(1.5, delay[0] * 1.3)
            assert stage.get_setting("max_rate") == P.SETTINGS["max_rate"].default
        c = stage.counters
        assert c["worst_round_trip_s"] >= 1.4
        assert c["longest_command_s"] > stage.timeout  # longer than the fixed timeout, and fine
        assert c["resends"] <= c["commands"] // 2
        assert c["over_budget"] == 0
    finally:
        stage.close()
        time.sleep(delay[0])  # the last replies land before the pty closes
        fake.close()
