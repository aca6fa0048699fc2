"""The front panel: the button, the status light and the small display, run by one thread.

Why a thread of its own: the button is polled (hw/gpio.py) and the display redrawn only when
its lines change, every `interval` seconds, whatever the scan, the web or a commissioning step
is doing; a flaky I2C bus is logged and the loop carries on.

The button: a short press starts a scan with the current settings, or cancels the running one;
a long press (held ~2 s) copies the newest finished job's G-code onto the USB stick
(usbexport.py) in a thread of its own. The light is steady while the bench works and blinks
slowly after a failure. The display shows, first found wins:
  1. a notice (the USB copy's outcome) for NOTICE_S,
  2. what a commissioning step asks of the person at the bench,
  3. the first-run password until somebody has logged in (firstrun.py),
  4. the scan's state, level, progress and time left;
and always the box's address on its last line.

FrontPanel(service) uses of the service: state(), start_scan(), cancel(), export_latest_gcode(),
scan_running(), store.event(), publish(notice=...), and the commissioning session (commissioner) and first-run
password (first_run) it holds.
"""

from __future__ import annotations

import logging
import socket
import threading
import time

from ..errors import InkSliceError
from ..hw.devices import Devices
from .notices import usb_notice
from .store import ACTIVE

log = logging.getLogger("inkslice.panel")
NOTICE_S = 30.0  # how long a front-panel notice (USB copy) holds the display


def lan_address() -> str:
    """This box's LAN address, for the display (a UDP connect sends nothing)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("10.255.255.255", 1))
            return s.getsockname()[0]
    except OSError:
        return "no network"


def open_panel(factory) -> Devices:
    """The factory's button, light and display; a panel that cannot open is reported, not fatal."""
    try:
        panel = factory.open_panel()
    except InkSliceError as e:
        log.warning("front panel unavailable: %s", e)
        panel = Devices(None, None, hardware={"panel": f"fault: {e}"})
    for name, status in panel.hardware.items():
        if status != "ok":
            log.warning("%s: %s (carrying on without it)", name, status)  # reported once
    return panel


def display_lines(st: dict) -> list[str]:
    """A scan's state on the display: STATE, the level, done/total and the time left."""
    level = f"level {st['level_mm']:.2f} mm" if st["level_mm"] is not None else ""
    progress = f"{st['levels_done']}/{st['levels_total']}" if st["levels_total"] else ""
    if st["eta_s"]:
        progress += f"  {int(st['eta_s']) // 60}:{int(st['eta_s']) % 60:02d} left"
    return [st["state"].upper(), level, progress, lan_address()]


class FrontPanel:
    def __init__(self, service, devices: Devices, interval_s: float):
        self.service = service
        self.devices = devices
        self.interval_s = interval_s
        self._lock = threading.Lock()
        self._shown_notice: tuple[float, list[str]] | None = None  # (until, lines) on the display
        self._usb_thread: threading.Thread | None = None
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="inkslice-panel", daemon=True)

    @property
    def operator(self):
        return self.devices.operator

    def start(self) -> None:
        self._thread.start()

    def alive(self) -> bool:
        return self._thread.is_alive()

    def close(self) -> None:
        self._closing.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        if self._usb_thread is not None:
            self._usb_thread.join(timeout=30)  # let a copy finish its fsync and verification
        self.devices.close()

    def notify(self, notice: dict, log_it: bool = True) -> dict:
        """A front-panel outcome: on the display for NOTICE_S, in the state, in the event log."""
        lines = notice.pop("lines")
        with self._lock:
            self._shown_notice = (time.monotonic() + NOTICE_S, lines)
        self.service.publish(notice=notice)
        if log_it:
            (log.info if notice.get("ok", True) else log.warning)("button: %s", notice["text"])
            self.service.store.event(None, notice["kind"], notice["text"])
        return notice

    # -- the loop ------------------------------------------------------------------------
    def _loop(self) -> None:
        tick = 0
        last_lines = None
        while not self._closing.wait(self.interval_s):
            tick += 1
            try:
                self._poll_button()
                st = self.service.state()
                self._drive_led(st, tick)
                lines = (
                    self._notice_lines()
                    or self._commissioning_lines(st)
                    or self._password_lines(st)
                    or display_lines(st)
                )
                if lines != last_lines and self.devices.display is not None:
                    self.devices.display.show(lines)
                    last_lines = lines
            except Exception as e:  # a flaky I2C bus must not kill the panel
                log.warning("front panel: %s", e)

    def _poll_button(self) -> None:
        press = self.devices.button.poll() if self.devices.button is not None else None
        if not press:
            return
        if press == "long":
            self._start_usb_export()
            return
        with self._lock:
            self._shown_notice = None  # any short press gives the display back to the scan
        if self.service.scan_running():
            log.info("button: cancelling the scan")
            threading.Thread(target=self.service.cancel, daemon=True).start()
        else:
            log.info("button: starting a scan with the current settings")
            self.service.start_scan({"name": "started at the bench"})

    def _start_usb_export(self) -> None:
        if self._usb_thread is not None and self._usb_thread.is_alive():
            self.notify(usb_notice("busy"), log_it=False)
            return
        log.info("button: long press, copying the latest G-code to the USB stick")
        self._usb_thread = threading.Thread(
            target=self.service.export_latest_gcode, name="inkslice-usb", daemon=True
        )
        self._usb_thread.start()

    def _drive_led(self, st: dict, tick: int) -> None:
        if self.devices.led is None:
            return
        s = st["state"]
        # steady on while working, slow blink when failed, off otherwise
        self.devices.led.set(s in ACTIVE or (s == "failed" and tick % 4 < 2))

    # -- what the display shows ----------------------------------------------------------
    def _notice_lines(self) -> list[str] | None:
        with self._lock:
            shown = self._shown_notice
            if shown is None:
                return None
            if time.monotonic() > shown[0]:
                self._shown_notice = None
                return None
        return [*shown[1], lan_address()]

    def _commissioning_lines(self, st: dict) -> list[str] | None:
        """What a commissioning step asks of the person at the bench; a scan's progress (the
        reference ball's) takes the screen while it runs."""
        session = self.service.commissioner.session
        if session is None or st["state"] in ACTIVE:
            return None
        return [*session.display_lines(), lan_address()]

    def _password_lines(self, st: dict) -> list[str] | None:
        """The first-run password while nobody has logged in; a scan's progress takes the screen."""
        if st["state"] in ACTIVE:
            return None
        password = self.service.first_run.pending()
        if not password:
            return None
        return ["FIRST LOGIN", "admin password:", password, lan_address()]
