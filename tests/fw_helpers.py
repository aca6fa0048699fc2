"""Shared pieces of the firmware tests (tests/test_fw_*.py).

The fixtures (in conftest.py) build everything they need with make (CI starts from
a clean clone): the AVR ELF and the simavr harness once per session, the cmocka and
fuzzer binaries in their own tests.  RawLink speaks the line protocol by hand
so the protocol tests can send exactly the bytes a spec case describes.
"""

import subprocess
import time

import serial
from polling import wait_until

from appliance.firmware import build_dir
from appliance.hw import protocol as P
from appliance.sim.hil import FIRMWARE_DIR

BUILD = build_dir()


def make(*targets, check=True):
    BUILD.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(
        ["make", "-C", str(FIRMWARE_DIR), f"BUILD={BUILD}", *targets], capture_output=True, text=True
    )
    if check and r.returncode != 0:
        raise AssertionError(f"make {' '.join(targets)} failed:\n{r.stdout}\n{r.stderr}")
    return r


class RawLink:
    """The protocol by hand: exact lines in, parsed lines out."""

    def __init__(self, port, timeout=5.0):  # generous: CI machines are shared and loaded
        self.ser = serial.Serial(port, 115200, timeout=timeout)
        self.timeout = timeout

    def send_raw(self, data: bytes):
        self.ser.write(data)

    def send(self, seq, verb, *args) -> bytes:
        data = P.encode_command(seq, verb, *args, check=False)  # unknown verbs too: the firmware's to refuse
        self.ser.write(data)
        return data

    def line(self, timeout=None):
        """The next intact line, parsed (Reply, Status or Banner)."""
        deadline = time.monotonic() + (timeout or self.timeout)
        while time.monotonic() < deadline:
            raw = self.ser.readline()
            if raw.endswith(b"\n"):
                try:
                    return P.parse_line(raw)
                except P.ProtocolError:
                    continue  # e.g. the tail of a boot banner sent before the port was opened
        raise AssertionError("no line from the firmware")

    def reply(self, seq=None, timeout=None):
        while True:
            item = self.line(timeout)
            if isinstance(item, P.Reply) and (seq is None or item.seq == seq):
                return item

    def ask(self, seq, verb, *args) -> P.Reply:
        self.send(seq, verb, *args)
        return self.reply(seq)

    def status(self) -> P.Status:
        self.ser.reset_input_buffer()
        self.ser.write(P.RT_STATUS)
        while True:
            item = self.line()
            if isinstance(item, P.Status):
                return item

    def wait_idle(self, timeout=120.0) -> P.Status:
        def settled():
            st = self.status()
            return st if st.state not in ("moving", "homing") else None

        return wait_until(settled, timeout, what="the controller to be idle", every=0.005)

    def close(self):
        self.ser.close()


def err(name):
    return P.ERROR_NUMBER[name]
