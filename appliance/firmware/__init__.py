"""The stage controller's firmware, shipped inside the package.

The AVR sources (stepper/src), the code table both sides read (stepper/codes.def:
the C build includes it, appliance/hw/protocol.py parses it at import) and the
simavr harness (stepper/sim/hil.c) are package data.  An installed copy can
therefore build and flash the firmware and run the simulated bench with no
checkout beside it.

Build outputs never go next to the sources (site-packages is read-only on a
box, and a checkout's tree should stay clean): make writes them to a cache
folder of their own, one per source tree, so two checkouts or an installed
copy never pick up each other's objects.

    build(("firmware",))            # the ELF and HEX, in build_dir()
    flash("/dev/inkslice-stage")    # build, then avrdude through the Arduino bootloader
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import threading
from pathlib import Path

from ..errors import DeviceError, SettingError

SOURCE = Path(__file__).resolve().parent / "stepper"
HEX = "inkslice-stepper.hex"
ELF = "inkslice-stepper.elf"
MCU = "m328p"                   # avrdude's name for the ATmega328P
_build_lock = threading.Lock()


def source_dir() -> Path:
    """The firmware sources; INKSLICE_FIRMWARE_DIR points at another tree (firmware work)."""
    env = os.environ.get("INKSLICE_FIRMWARE_DIR")
    return Path(env) if env else SOURCE


def codes_path() -> Path:
    return source_dir() / "codes.def"


def build_dir() -> Path:
    """Where make writes: INKSLICE_FIRMWARE_BUILD, else the user's cache folder,
    one sub-folder per source tree."""
    env = os.environ.get("INKSLICE_FIRMWARE_BUILD")
    if env:
        return Path(env)
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    tree = hashlib.sha1(str(source_dir().resolve()).encode()).hexdigest()[:10]
    return cache / "inkslice" / f"firmware-{tree}"


def make(*targets: str) -> subprocess.CompletedProcess:
    """make in the source tree with BUILD pointing at build_dir(); raises on failure."""
    out = build_dir()
    with _build_lock:
        try:
            out.mkdir(parents=True, exist_ok=True)
            r = subprocess.run(["make", "-s", "-C", str(source_dir()), f"BUILD={out}", *targets],
                               capture_output=True, text=True)
        except OSError as e:
            raise DeviceError(out, f"cannot build the firmware ({e.strerror or e})") from None
    if r.returncode != 0:
        raise DeviceError(source_dir(), f"building {' '.join(targets)} failed:\n{r.stdout}{r.stderr}")
    return r


def build(targets=("all",)) -> Path:
    """make the targets (default: firmware and simavr harness); return the build folder."""
    make(*targets)
    return build_dir()


def avrdude_command(port: str, hex_file: Path, programmer: str = "arduino", baud: int = 115200) -> list[str]:
    """The command that writes hex_file through the board's bootloader (the Uno's
    is 115200 baud; old Nano bootloaders want 57600)."""
    return ["avrdude", "-p", MCU, "-c", programmer, "-P", str(port), "-b", str(baud), "-D",
            "-U", f"flash:w:{hex_file}:i"]


def flash(port: str, programmer: str = "arduino", baud: int = 115200, dry_run: bool = False) -> list[str]:
    """Build the HEX and write it to the controller on `port`; return the avrdude command.
    The daemon must not hold the port meanwhile (stop inkslice-daemon first)."""
    if not port:
        raise SettingError("--port", "name the controller's serial port")
    hex_file = build(("firmware",)) / HEX
    cmd = avrdude_command(port, hex_file, programmer, baud)
    if dry_run:
        return cmd
    if shutil.which("avrdude") is None:
        raise DeviceError("avrdude", "not installed (apt-get install avrdude)")
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        tail = (r.stderr or r.stdout).strip().splitlines()[-3:]
        raise DeviceError(port, "avrdude failed: " + " / ".join(tail))
    return cmd
