"""SimulatedBench: the real stepper firmware running under simavr, with a stage.

    with SimulatedBench() as bench:
        stage = SerialStage(bench.port)
        stage.home(); stage.move_to(12.5)
        bench.stage_position_mm()     # where the stage really is, from counted STEP edges

The harness (appliance/firmware/stepper/sim/hil.c) runs the unmodified ELF, bridges its
UART to a pseudo-terminal, moves a simulated stage one step per STEP edge
and closes the limit switches at the ends of travel.  This class starts it,
talks to its control channel (stdin/stdout lines) and exposes the fault
switches.  The firmware and the harness are built with make on first use
(a no-op when they are up to date), into appliance.firmware.build_dir().

speed: simulated seconds per wall-clock second.  The default 10 homes the
stage in about a second and still sleeps most of the time (a few % of a
core); 1.0 behaves exactly like the real bench; 0 runs flat out (a busy
core; thousands of times real time while the firmware sleeps, ~3x while it
steps): for soak tests and benches.  Stepping never runs faster than the
host can simulate it (~3x real time), whatever the speed.
"""

from __future__ import annotations

import subprocess
import threading
from pathlib import Path

from appliance.errors import DeviceError
from appliance.firmware import build, source_dir

FIRMWARE_DIR = source_dir()
F_CPU = 16_000_000
STEPS_PER_MM = 1600.0  # the simulated mechanics: 200 steps x 16 microsteps, 2 mm lead


class SimulatedBench:
    FAULT_KINDS = ("drop", "corrupt", "dup")

    def __init__(
        self,
        speed: float = 10.0,
        stage_mm: float = 40.0,
        seed: int = 1,
        elf: str | Path | None = None,
        steps_per_mm: float = STEPS_PER_MM,
        top_switch_mm: float = 98.0,
    ):
        build_dir = build()
        self.elf = Path(elf) if elf else build_dir / "inkslice-stepper.elf"
        self.steps_per_mm = steps_per_mm
        self._lock = threading.Lock()
        self._proc = subprocess.Popen(
            [
                str(build_dir / "hil"),
                str(self.elf),
                "--speed",
                str(speed),
                "--stage",
                str(round(stage_mm * steps_per_mm)),
                "--seed",
                str(seed),
                "--top-switch",
                str(round(top_switch_mm * steps_per_mm)),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            bufsize=1,
        )
        first = self._proc.stdout.readline().split()
        if len(first) != 2 or first[0] != "port":
            self._proc.kill()
            raise DeviceError("simulated bench", f"the harness did not start (said {first!r})")
        self.port = first[1]
        self._wait_for_banner(0)

    def _wait_for_banner(self, tx_before: int, timeout: float = 5.0) -> None:
        """Return once the firmware has started sending its boot banner: its
        UART and interrupts are then up, so no byte sent to it is lost."""
        import time

        deadline = time.monotonic() + timeout
        while self.stats()["tx_bytes"] <= tx_before:
            if time.monotonic() > deadline:
                raise DeviceError("simulated bench", f"the firmware sent no boot banner within {timeout} s")
            time.sleep(0.002)

    # ---- control channel ----
    def _ctl(self, line: str) -> str:
        with self._lock:
            if self._proc.poll() is not None:
                raise DeviceError("simulated bench", f"the harness has exited (code {self._proc.returncode})")
            self._proc.stdin.write(line + "\n")
            self._proc.stdin.flush()
            reply = self._proc.stdout.readline().strip()
        if not reply or reply.startswith("err") or reply.startswith("crashed"):
            raise DeviceError("simulated bench", f"'{line}' failed: {reply or 'no reply'}")
        return reply

    def stage_position_steps(self) -> int:
        return int(self._ctl("pos").split()[1])

    def stage_position_mm(self) -> float:
        """Where the simulated stage really is (counted STEP edges), mm above the home switch."""
        return self.stage_position_steps() / self.steps_per_mm

    def cycle(self) -> int:
        return int(self._ctl("pos").split()[2])

    def stats(self) -> dict:
        fields = self._ctl("stats").split()[1:]
        return {k: int(v) for k, v in (f.split("=") for f in fields)}

    def set_fault(self, direction: str, kind: str, rate: float) -> None:
        """direction 'rx' (host to MCU) or 'tx'; kind drop/corrupt/dup; rate a fraction of bytes."""
        if direction not in ("rx", "tx") or kind not in self.FAULT_KINDS or not 0 <= rate <= 1:
            raise ValueError(f"fault {direction} {kind} {rate}: want rx|tx, drop|corrupt|dup, 0..1")
        self._ctl(f"fault {direction} {kind} {round(rate * 1e6)}")

    def set_faults(self, rate: float) -> None:
        """Spread `rate` evenly over the three kinds, both directions."""
        for d in ("rx", "tx"):
            for k in self.FAULT_KINDS:
                self.set_fault(d, k, rate / 3)

    def clear_faults(self) -> None:
        self.set_faults(0.0)

    def reset_mcu(self, wait_boot: bool = False) -> None:
        """Pulse the MCU's reset pin: the firmware reboots, EEPROM survives, the
        stage stays where it is.  wait_boot: return only once it has booted."""
        before = self.stats()["tx_bytes"]
        self._ctl("reset")
        if wait_boot:
            self._wait_for_banner(before)

    def set_speed(self, speed: float) -> None:
        self._ctl(f"speed {speed}")

    def place_stage(self, mm: float) -> None:
        self._ctl(f"stage {round(mm * self.steps_per_mm)}")

    def record_edges(self, path: str | Path | None) -> None:
        self._ctl(f"record {path}" if path else "record off")

    def eeprom(self, addr: int, value: int | None = None) -> int | None:
        if value is None:
            return int(self._ctl(f"eeprom {addr}").split()[2])
        self._ctl(f"eeprom {addr} {value}")
        return None

    def close(self) -> None:
        if self._proc.poll() is None:
            try:
                self._proc.stdin.write("quit\n")
                self._proc.stdin.flush()
                self._proc.wait(timeout=2)
            except (OSError, subprocess.TimeoutExpired, ValueError):
                self._proc.kill()
                self._proc.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
