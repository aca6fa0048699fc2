"""SerialStage: the lifting stage, driven over the controller's line protocol.

The rules it follows (appliance/firmware/stepper/PROTOCOL.md has the whole contract):

* One command at a time.  Each goes out with a new sequence number and a
  CRC; the driver waits for the reply carrying that number.  No reply in
  `reply_timeout`, a reply whose CRC fails, or an `error:1` (the controller
  saw a damaged line) means: send the very same line again.  The controller
  answers a repeated (seq, crc) with its remembered reply and does not
  execute it twice, so resending MOVE is safe.  After `timeout` seconds of
  trying the driver gives up with a DeviceError: it never hangs.
* MOVE targets are absolute step counts.  Whatever gets lost, re-issuing a
  move to the same target after a recovery cannot move the stage twice.
* Motion is complete when a status report says idle, homed, at the target.
  Status goes by the real-time '?' byte, which works even mid-line.
* A reset of the MCU loses the position (homed flag off, fresh_boot on).
  The driver notices it in the next status or reply, re-homes (unless
  auto_rehome=False, then it raises) and re-issues the interrupted move.
  The counters in `.counters` say how often each of these happened.
* The waits follow the line, not a fixed clock.  Every reply that answers a
  single send is a round-trip sample; the wait for one reply is the smoothed
  round trip plus four deviations (as TCP does), never below `reply_timeout`,
  and half as long again after each silent one.  A damaged reply is no
  silence (the link answered, noise hit it): the line goes out again at once,
  the wait unchanged.  A command may keep trying for
  `timeout` or ATTEMPTS such waits, whichever is longer: on a slow link (a
  loaded host, a USB hub) commands get the time the link needs, while a dead
  line, which gives no samples, still fails after `timeout`.
"""

from __future__ import annotations

import os
import threading
import time

import serial

from appliance.errors import DeviceError, SettingError
from appliance.hw import protocol as P
from appliance.hw.base import Stage, StageStatus
from appliance.hw.roundtrip import RoundTrip

BAUD = 115200
ATTEMPTS = 8  # a command's budget: at least this many waits at the measured pace
DAMAGED = object()  # _readline's answer for a line that arrived whole but damaged
RESEND = object()  # an answer that asks for the line again at once (the controller saw it damaged)


class SerialStage(Stage):
    def __init__(
        self,
        port: str,
        steps_per_mm: float | None = None,
        timeout: float = 3.0,
        reply_timeout: float = 0.15,
        auto_rehome: bool = True,
        poll_interval: float = 0.004,
    ):
        self.port_name = port
        self.timeout = float(timeout)
        self.reply_timeout = float(reply_timeout)
        self.auto_rehome = auto_rehome
        self.poll_interval = poll_interval
        self.counters = dict(
            commands=0,
            resends=0,
            damaged_lines=0,
            status_polls=0,
            resets_seen=0,
            spurious_estops=0,
            rehomes=0,
            reissued_moves=0,
            idle_off_target=0,
            longest_command_s=0.0,
            worst_round_trip_s=0.0,
            longest_budget_s=0.0,
            over_budget=0,
        )
        self.rtt = RoundTrip(self.reply_timeout)
        self._stop_requested = False
        self._ready = False  # the boot banner seen while connecting is no reset
        # one lost position is seen several ways (a banner, a fresh_boot status, a MOVE refused
        # with not_homed): it is counted once, until a home finds the position again
        self._loss_counted = False
        self._lock = threading.RLock()
        self._seq = int.from_bytes(os.urandom(2), "big") % 60000 + 1  # unlike a previous session's last seq
        self._target: int | None = None
        try:
            self._ser = serial.serial_for_url(port, BAUD, timeout=self.reply_timeout)
        except (serial.SerialException, OSError) as e:
            raise DeviceError(f"stage {port}", f"cannot open the serial port: {e}") from None
        try:
            self.info = self.identify()
            self._settings = {
                name: self.get_setting(name)
                for name in ("steps_per_rev", "lead_um", "soft_min", "soft_max", "max_rate", "accel")
            }
        except Exception:
            self._ser.close()
            raise
        if steps_per_mm is None:
            steps_per_mm = self._settings["steps_per_rev"] * 1000.0 / self._settings["lead_um"]
        if not steps_per_mm > 0:
            raise SettingError("steps_per_mm", f"must be positive, got {steps_per_mm}")
        self.steps_per_mm = float(steps_per_mm)
        self._ready = True

    # ---- low level -------------------------------------------------------
    def _where(self) -> str:
        return f"stage {self.port_name}"

    def _next_seq(self) -> int:
        self._seq = self._seq % 65535 + 1
        return self._seq

    def _readline(self, deadline: float):
        """One intact line before the deadline: None on timeout, DAMAGED (counted) if it fails."""
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._ser.timeout = left
            raw = self._ser.readline()
            if not raw:
                return None
            if not raw.endswith(b"\n") or not raw.strip():
                continue  # a fragment the timeout cut, or the newline a banner opens with
            try:
                return P.parse_line(raw)
            except P.ProtocolError:
                self.counters["damaged_lines"] += 1
                return DAMAGED

    def budget(self) -> float:
        """How long one command may keep trying: `timeout`, or longer on a link measured slow."""
        return max(self.timeout, ATTEMPTS * self.rtt.wait())

    def _note_round_trip(self, rtt: float) -> None:
        self.rtt.sample(rtt)
        self.counters["worst_round_trip_s"] = self.rtt.worst

    def _note_took(self, start: float, budget: float) -> None:
        took = time.monotonic() - start
        self.counters["longest_command_s"] = max(self.counters["longest_command_s"], took)
        self.counters["longest_budget_s"] = max(self.counters["longest_budget_s"], budget)
        if took > budget:
            self.counters["over_budget"] += 1

    def _note_reset(self):
        self._note_loss("resets_seen")

    def _note_loss(self, counter: str):
        if self._ready and not self._loss_counted:
            self.counters[counter] += 1
            self._loss_counted = True

    def _exchange(self, send, answers):
        """send(tries) until answers(line) is true for an intact line (RESEND: send again now)
        -> (that line, or None when the budget ran out; tries; budget)."""
        start = time.monotonic()
        budget = self.budget()
        deadline = start + budget
        tries = 0
        while time.monotonic() < deadline:
            tries += 1
            send(tries)
            sent = time.monotonic()
            attempt_end = min(deadline, sent + self.rtt.wait())
            while True:
                item = self._readline(attempt_end)
                if item is None:
                    self.rtt.silence()  # silence: send again, waiting longer
                    break
                if item is DAMAGED:
                    break  # perhaps the answer, hit by noise: send again now
                if isinstance(item, P.Banner):
                    self._note_reset()
                    continue
                verdict = answers(item)
                if verdict is RESEND:
                    break
                if verdict:
                    if tries == 1:  # Karn: only the answer to a single send is a sample
                        self._note_round_trip(time.monotonic() - sent)
                    self._note_took(start, budget)
                    return item, tries, budget
        return None, tries, budget

    def transact(self, verb: str, *args) -> P.Reply:
        """Send one command until a reply to it arrives; return the reply (ok or error)."""
        with self._lock:
            seq = self._next_seq()
            data = P.encode_command(seq, verb, *args)
            self.counters["commands"] += 1

            def send(tries):
                if tries > 1:
                    self.counters["resends"] += 1
                self._ser.write(data)

            def answers(item):
                if not isinstance(item, P.Reply) or item.seq not in (seq, 0):
                    return False  # a stray status report or an older reply
                if not item.ok and item.error == P.ERROR_NUMBER["bad_checksum"]:
                    return RESEND  # a damaged line, perhaps ours
                return item.seq == seq

            reply, tries, budget = self._exchange(send, answers)
            if reply is None:
                raise DeviceError(
                    self._where(),
                    f"no valid reply to {verb} after {tries} tries in "
                    f"{budget:.1f} s: is the controller connected and powered?",
                )
            return reply

    def command(self, verb: str, *args) -> str:
        """transact() and turn an error reply into a DeviceError naming the code."""
        r = self.transact(verb, *args)
        if not r.ok:
            raise DeviceError(
                self._where(),
                f"{verb} {' '.join(map(str, args))} refused: error:{r.error} {r.error_name} ({r.error_text})",
            )
        return r.payload

    def raw_status(self) -> P.Status:
        """A real-time status report ('?'), retried until one arrives intact."""

        def send(tries):
            self._ser.reset_input_buffer()  # drop stale reports
            self._ser.write(P.RT_STATUS)
            self.counters["status_polls"] += 1

        with self._lock:
            report, _, budget = self._exchange(send, lambda item: isinstance(item, P.Status))
        if report is None:
            raise DeviceError(self._where(), f"no status report in {budget:.1f} s")
        return report

    # ---- the Stage interface ---------------------------------------------
    def identify(self) -> dict:
        try:
            r = self.transact("ID")
        except DeviceError:
            raise DeviceError(
                self._where(),
                f"no reply to ID at {BAUD} baud: is this the InkSlice "
                "stepper controller (appliance/firmware)?",
            ) from None
        info = P.parse_identity(r.payload) if r.ok else {}
        if not r.ok or info.get("name") != "inkslice-stepper":
            raise DeviceError(
                self._where(),
                f"the device does not identify as inkslice-stepper (reply {r.payload or r.error_name!r})",
            )
        if info.get("proto") != P.PROTO_VERSION:
            raise DeviceError(
                self._where(),
                f"firmware speaks protocol {info.get('proto')!r} but this driver "
                f"speaks protocol {P.PROTO_VERSION}: flash this version's firmware "
                "(`inkslice firmware flash`, the daemon stopped)",
            )
        return info

    def get_setting(self, name: str) -> int:
        if name not in P.SETTINGS:
            raise SettingError(f"stage setting {name}", "no such setting")
        return int(self.command("GET", name))

    def set_setting(self, name: str, value: int) -> None:
        s = P.SETTINGS.get(name)
        if s is None:
            raise SettingError(f"stage setting {name}", "no such setting")
        if int(value) != value or not s.low <= value <= s.high:
            raise SettingError(f"stage setting {name}", f"{value} is outside {s.low}..{s.high} ({s.text})")
        self.command("SET", name, int(value))
        if name in self._settings:
            self._settings[name] = int(value)

    def status(self) -> StageStatus:
        st = self.raw_status()
        flags = dict(st.flags)
        flags["alarm"] = st.alarm
        return StageStatus(
            state=st.state,
            position_steps=st.position,
            position_mm=st.position / self.steps_per_mm,
            homed=st.homed,
            flags=flags,
        )

    def _lost(self, st: P.Status) -> bool:
        """The position is gone through no fault of the bench: the MCU was
        reset, or line noise forged an emergency-stop byte we never sent."""
        return bool(st.flags.get("fresh_boot")) or (st.state == "estop" and not self._stop_requested)

    def _wait(self, done, what: str, deadline: float) -> P.Status:
        """Poll until done(status) is true; alarms raise; a lost position returns the status for recovery."""
        while True:
            st = self.raw_status()
            if self._lost(st):
                if st.state == "estop":
                    self._note_loss("spurious_estops")
                return st
            if st.state in ("alarm", "estop"):
                raise DeviceError(
                    self._where(),
                    f"{what} stopped: state {st.state}, alarm {st.alarm} "
                    f"({P.ALARMS_BY_NAME[st.alarm].text if st.alarm in P.ALARMS_BY_NAME else ''}); "
                    "home the stage to clear it",
                )
            if done(st):
                return st
            if time.monotonic() > deadline:
                raise DeviceError(
                    self._where(),
                    f"{what} did not finish in time (state {st.state}, position {st.position} steps)",
                )
            time.sleep(self.poll_interval)

    def _recover_or_raise(self, what: str):
        if self._stop_requested:
            raise DeviceError(
                self._where(), f"{what} refused: the stage was emergency-stopped; home it first"
            )
        self._note_reset()
        if not self.auto_rehome:
            raise DeviceError(
                self._where(), f"the controller was reset during {what}: position unknown, home first"
            )
        self.counters["rehomes"] += 1

    def home(self, timeout: float = 60.0) -> None:
        with self._lock:
            deadline = time.monotonic() + timeout
            while True:
                r = self.transact("HOME")
                if not r.ok and r.error == P.ERROR_NUMBER["busy"]:
                    self._wait(lambda s: s.state not in ("moving", "homing"), "waiting for idle", deadline)
                    continue
                if not r.ok:
                    raise DeviceError(self._where(), f"HOME refused: error:{r.error} {r.error_name}")
                self._stop_requested = False
                st = self._wait(lambda s: s.state == "idle" and s.homed, "homing", deadline)
                if self._lost(st):
                    self._note_reset()  # reset mid-homing: start over
                    continue
                self._target = st.position
                self._loss_counted = False
                return

    def move_to(self, position_mm: float, timeout: float = 60.0) -> None:
        self.move_to_steps(round(position_mm * self.steps_per_mm), timeout)

    def move_by(self, delta_mm: float, timeout: float = 60.0) -> None:
        base = self._target if self._target is not None else self.raw_status().position
        self.move_to_steps(base + round(delta_mm * self.steps_per_mm), timeout)

    def move_to_steps(self, target: int, timeout: float = 60.0) -> None:
        lo, hi = self._settings["soft_min"], self._settings["soft_max"]
        if not lo <= target <= hi:
            raise SettingError(
                "stage move",
                f"{target / self.steps_per_mm:.4f} mm is outside the soft limits "
                f"{lo / self.steps_per_mm:.3f}..{hi / self.steps_per_mm:.3f} mm",
            )
        with self._lock:
            deadline = time.monotonic() + timeout
            issued = 0
            while True:
                if time.monotonic() > deadline:
                    raise DeviceError(
                        self._where(), f"move to {target} steps did not finish in {timeout:.1f} s"
                    )
                r = self.transact("MOVE", target)
                if not r.ok:
                    if r.error == P.ERROR_NUMBER["not_homed"]:
                        # lost since the last status: a forged Ctrl-X leaves the state at
                        # estop, a reset does not
                        if not self._stop_requested and self.raw_status().state == "estop":
                            self._note_loss("spurious_estops")
                        self._recover_or_raise("a move")
                        self.home(max(1.0, deadline - time.monotonic()))
                        continue
                    if r.error == P.ERROR_NUMBER["busy"]:
                        self._wait(
                            lambda s: s.state not in ("moving", "homing"), "waiting for idle", deadline
                        )
                        continue
                    raise DeviceError(
                        self._where(),
                        f"MOVE {target} refused: error:{r.error} {r.error_name} ({r.error_text})",
                    )
                if issued:
                    self.counters["reissued_moves"] += 1
                issued += 1
                stuck = 0
                while True:
                    st = self._wait(lambda s: s.state == "idle", "move", deadline)
                    if self._lost(st) or not st.homed:
                        self._recover_or_raise("a move")
                        self.home(max(1.0, deadline - time.monotonic()))
                        break  # re-issue the move from the new home
                    if st.position == target:
                        self._target = target
                        return
                    stuck += 1  # idle elsewhere: a stale report, or a lost move
                    self.counters["idle_off_target"] += 1
                    if stuck >= 3:
                        break
                    time.sleep(self.poll_interval)

    def travel_mm(self) -> tuple[float, float]:
        return self._settings["soft_min"] / self.steps_per_mm, self._settings["soft_max"] / self.steps_per_mm

    def stop(self) -> None:
        """Emergency stop: three Ctrl-X bytes (one may be lost on the wire),
        outside the command lock so it preempts a move in progress."""
        self._stop_requested = True
        self._ser.write(P.RT_ESTOP * 3)
        deadline = time.monotonic() + self.budget()
        with self._lock:
            while time.monotonic() < deadline:
                st = self.raw_status()
                if st.state == "estop":
                    self._target = None
                    return
                self._ser.write(P.RT_ESTOP)
            raise DeviceError(self._where(), "emergency stop not confirmed by the controller")

    def close(self) -> None:
        try:
            self._ser.close()
        except Exception:
            pass
