"""BenchService: the daemon's public face. It implements facade.Bench (daemon/facade.py, the
one list of what the daemon offers, with each method's meaning); the web UI, the CLI and the
tests use only those methods, in-process or over the socket (rpc.BenchClient).

    service = BenchService(data_dir, factory)      # factory: devices.py / sim.fakes
    job_id = service.start_scan({"name": "mouse", "level_step_mm": 1.0})
    for state in service.subscribe(timeout=30): ...
    service.job(job_id)["outputs"]; service.job_file(job_id, "toolpath.gcode")

Thread-safe: one lock guards the state; one background thread runs a scan at
a time (runner.py); one panel thread polls the button and drives the status
LED and display. The button: a short press starts or stops a scan, a long
press (held ~2 s, see hw/gpio.py) copies the newest job's G-code to the USB
stick (hw/usb.py) in a thread of its own; the outcome is shown on the display,
in state()["notice"] (the web UI's dashboard) and in the event log.

A job that ends done or failed, and an interrupted scan found at start, are also sent to the
webhook setting's address (webhook.py).

Device factories are injected so the same service drives
the real bench, the simulated one (firmware under simavr + virtual camera)
or the in-memory fakes: a device factory is a hw.base.BenchFactory.
"""

from __future__ import annotations

import copy
import logging
import queue
import secrets
import shutil
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from ..errors import Cancelled, DeviceError, InkSliceError, SettingError
from ..hw.base import HumanOperator
from ..hw.devices import Devices
from ..hw.usb import NoStick
from ..scanfile import load_scan
from . import backup as backups
from . import importing, processing
from . import settings as S
from .calibration import GuidedCalibration
from .commissioning import Commissioning, reference_processor
from .eta import JobTimes
from .firstrun import Pending
from .levels import LevelPlan
from .livemap import LiveMap
from .manual import ManualSession
from .notices import usb_notice
from .processing import PROGRAM, child_process
from .recovery import recover
from .runner import ScanRunner, free_mb
from .store import ACTIVE, DiskFull, Store
from .webhook import Webhook

log = logging.getLogger("inkslice.service")
STATES = ("idle", "homing", "scanning", "processing", "done", "failed", "cancelled")
NOTICE_S = 30.0  # how long a front-panel notice (USB copy) holds the display
GCODE_SUFFIXES = (".gcode", ".nc", ".ngc", ".tap")


def lan_address() -> str:
    """This box's LAN address, for the display (a UDP connect sends nothing)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("10.255.255.255", 1))
            return s.getsockname()[0]
    except OSError:
        return "no network"


def _box_uptime() -> float | None:
    try:
        return float(Path("/proc/uptime").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


class BenchService:
    def __init__(
        self,
        data_dir,
        factory,
        processor: Callable = child_process,
        disk_free_mb: Callable = free_mb,
        panel_interval_s: float = 0.25,
        usb=None,
    ):
        self.data_dir = Path(data_dir)
        self.store = Store(self.data_dir)
        self.factory = factory
        self.processor = processor
        self.disk_free_mb = disk_free_mb
        self.usb = usb  # hw.usb.UsbExporter (sticks(), export()); None: no USB export
        self._usb_thread: threading.Thread | None = None
        self._shown_notice: tuple[float, list[str]] | None = None  # (until, lines) on the display
        self._first_run = Pending(self.data_dir)  # the web's first-run password, until the first login
        self._live: tuple[str, LiveMap] | None = None  # (job id, its height map so far)
        self._calibration: GuidedCalibration | None = None
        self._lock = threading.RLock()
        self._state = {
            "state": "idle",
            "job_id": None,
            "level_mm": None,
            "levels_done": 0,
            "levels_total": 0,
            "eta_s": None,
            "eta_processing_s": None,
            "message": "ready",
            "hardware": {},
            "notice": None,
            "manual": {"open": False, "light": False, "homed": False, "level_mm": None},
        }
        self._subscribers: list[queue.Queue] = []
        self._frame = None
        self._job_settings = {}
        self._devices = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._closing = threading.Event()
        self._started = time.time()
        self.webhook = Webhook(self.settings)
        self.interrupted = recover(self.store)
        if self.interrupted:
            last = self.store.get_job(self.interrupted[0])
            self._state.update(
                state="failed",
                job_id=last["id"],
                message=last["reason"],
                levels_done=last["levels_done"],
                levels_total=last["levels_total"],
            )
            if not self.settings()["auto_resume"]:
                self.webhook.send(
                    "needs_attention",
                    last,
                    f"the scan was interrupted ({last['reason']}); resume it or start again",
                )
        self._panel = self._open_panel()
        self._commissioning = Commissioning(self.store, self._commissioning_hooks())
        self._times = JobTimes(self.data_dir)
        self._sizes: dict[str, tuple] = {}  # job id -> ((status, finished), bytes on disk)
        self._manual = ManualSession(
            self._open_for_panel, self.settings, self._show_frame, self._manual_report
        )
        self._panel_thread = threading.Thread(
            target=self._panel_loop, args=(panel_interval_s,), name="inkslice-panel", daemon=True
        )
        self._panel_thread.start()
        if self.interrupted and self.settings()["auto_resume"]:
            self.resume(self.interrupted[0])

    # == the facade ===============================================================
    def state(self) -> dict:
        with self._lock:
            return copy.deepcopy(self._state)

    def start_scan(self, params: dict) -> str:
        params = dict(params or {})
        extra = set(self.factory.extra_params) | {"name"}
        for key in params:
            if key not in S.DEFAULTS and key not in extra:
                raise SettingError(key, "unknown scan parameter")
        with self._lock:
            self._refuse_if_busy()
            settings = S.validate(self.settings(), {k: v for k, v in params.items() if k in S.DEFAULTS})
            extras = {k: v for k, v in params.items() if k not in S.DEFAULTS}
            extras = self.factory.check(extras) or extras  # may fill in defaults (the surface)
            extras["name"] = str(params.get("name", ""))[:80]
            job_id = time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)
            total = LevelPlan(settings).estimate_total([])
            self.store.create_job(job_id, extras["name"], settings, extras, total)
            self._launch(job_id, total, 0)
            return job_id

    def cancel(self, wait_s: float = 30.0, reason: str = "cancelled by the operator") -> None:
        if self._calibration is not None and self._calibration.active:
            self.cancel_calibration(wait_s)  # a calibration left half-way gives the bench back
        if self._commissioning.holds_bench:
            self._commissioning.cancel(wait_s=wait_s)
        with self._lock:
            thread = self._thread
            if thread is None or not thread.is_alive():
                return
            self._stop.reason = reason
            self._stop.set()
            self._set(message="cancelling")
            devices = self._devices
        if devices is not None and devices.stage is not None:
            try:
                devices.stage.stop()  # preempts a long move or homing at once
            except Exception as e:
                log.warning("stop on cancel: %s", e)
        thread.join(timeout=wait_s)

    def resume(self, job_id: str) -> str:
        with self._lock:
            self._refuse_if_busy()
            job = self.store.get_job(job_id)
            if job["status"] not in ("failed", "cancelled"):
                raise SettingError(
                    "job",
                    f"job {job_id} is {job['status']}; only a failed, cancelled or "
                    "interrupted scan can be resumed",
                )
            self.store.update_job(
                job_id, status="homing", reason="", interrupted=0, finished=None, attempts=job["attempts"] + 1
            )
            self.store.event(job_id, "resumed", f"resumed (attempt {job['attempts'] + 1})")
            if job["params"].get("imported"):
                self._launch_import(job_id)  # nothing to capture: process it again
            else:
                self._launch(job_id, job["levels_total"], job["levels_done"])
            return job_id

    def jobs(self) -> list[dict]:
        return self.store.list_jobs()

    def job(self, job_id: str) -> dict:
        return self.store.get_job(job_id)

    def job_file(self, job_id: str, name: str) -> Path:
        """A file inside that job's folder (outputs, scan/scan.json, scan/frames/...); nothing else."""
        self.store.get_job(job_id)  # raises for an unknown job
        folder = self.store.job_dir(job_id).resolve()
        try:
            path = (folder / str(name)).resolve()
        except (OSError, ValueError):
            path = None
        if path is None or folder not in path.parents or not path.is_file() or path.name.endswith(".tmp"):
            raise InkSliceError(f"job {job_id}", f"no file named {name!r} in this job")
        return path

    def latest_frame(self):
        with self._lock:
            return self._frame

    def settings(self) -> dict:
        return S.full(self.store.load_settings())

    def update_settings(self, changes: dict) -> dict:
        with self._lock:
            new = S.validate(self.settings(), changes)
            self.store.save_settings({k: new[k] for k in changes})
            return new

    def subscribe(self, timeout: float = 30.0):
        """Yields the state dict now and on every change, for at most `timeout` seconds."""
        q: queue.Queue = queue.Queue(maxsize=200)
        with self._lock:
            self._subscribers.append(q)
            first = copy.deepcopy(self._state)
        end = time.monotonic() + timeout
        try:
            yield first
            while not self._closing.is_set():
                left = end - time.monotonic()
                if left <= 0:
                    return
                try:
                    yield q.get(timeout=min(left, 1.0))
                except queue.Empty:
                    continue
        finally:
            with self._lock:
                self._subscribers.remove(q)

    def events(self, job_id=None, limit=200) -> list[dict]:
        return self.store.events(job_id, limit)

    # == the extras the web UI offers when present ====================================
    def live_heightmap(self) -> dict | None:
        """The current (or last) scan's height map so far; None before the first frame."""
        with self._lock:
            live = self._live
        return live[1].to_json() if live else None

    def _guided(self) -> GuidedCalibration:
        with self._lock:
            if self._calibration is None:

                def open_devices():
                    self._manual.close()  # the panel's session gives the devices back
                    return self.factory.open(self.settings(), self._calibration_params())

                self._calibration = GuidedCalibration(
                    open_devices,
                    self.store,
                    self.settings(),
                    show_frame=self._show_frame,
                    operator=self._panel.operator,
                    **self.factory.calibration_target,
                )
            return self._calibration

    def _calibration_params(self) -> dict:
        return self.factory.check({}) or {}  # the simulated bench fills in its part

    def calibration(self) -> dict:
        return self._guided().describe()

    def calibrate(self, step: str) -> dict:
        """Do one guided step (in order: home, target, detect, accept); returns calibration().

        "cancel" at any step, also while one runs, gives the bench back (cancel_calibration)."""
        if step == "cancel":
            return self.cancel_calibration()
        cal = self._guided()
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                raise SettingError(
                    "calibration",
                    f"a scan is running ({self._state['job_id']}); calibrate when it has finished",
                )
            if step == "home" and self._commissioning.holds_bench:  # one owner of the devices at a time
                busy = self._commissioning.session.step
                raise SettingError(
                    "calibration",
                    f"the commissioning step {busy!r} holds the bench; finish it or "
                    f"cancel it first (POST /api/commissioning/{busy}/cancel)",
                )
        if not cal.lock.acquire(blocking=False):
            raise SettingError("calibration", "a calibration step is already running")
        try:
            cal.settings = self.settings()
            self._set(message=f"calibration: {step}")
            try:
                out = cal.do(step)
            except InkSliceError as e:
                self._set(message=f"calibration: {step} failed: {e.problem}")
                raise
            done = not cal.active
            self._set(
                message="calibration stored" if done and step == "accept" else f"calibration: {step} done"
            )
            if step == "accept":
                self.store.event(None, "calibrated", f"guided calibration stored: {cal.describe()}")
            return out
        finally:
            cal.lock.release()

    def cancel_calibration(self, wait_s: float = 30.0) -> dict:
        """Stop a guided calibration wherever it is: the stage stops, the devices close, the bench
        takes scans again and the steps start over at "home". Nothing is stored."""
        cal = self._calibration
        if cal is None:
            return self.calibration()
        cal.interrupt()  # a running step (homing, say) ends at once
        if not cal.lock.acquire(timeout=wait_s):
            raise SettingError("calibration", f"the running step did not stop within {wait_s:.0f} s")
        try:
            was_active = cal.active
            cal.close()
        finally:
            cal.lock.release()
        if was_active:
            self._set(message="calibration cancelled")
            self.store.event(None, "calibration", "guided calibration cancelled; the bench is free")
        return cal.describe()

    # -- the machine panel (manual.py) ------------------------------------------------------
    def preview(self) -> dict:
        """Keep the panel's session and its light on; a fresh frame in latest_frame(). Returns
        the panel's status ({"open", "light", "homed", "level_mm"}), also in state()["manual"].
        While a scan (or calibration, commissioning) holds the bench its own frames are the
        preview: the status then says why the panel is closed ("busy") instead of refusing."""
        try:
            return self._machine(self._manual.preview)
        except DeviceError as e:
            if self._manual.active or not self._bench_taken():
                raise
            return {**self._manual.status(), "busy": e.problem}

    def home_stage(self) -> dict:
        return self._machine(self._manual.home)

    def jog(self, mm: float) -> dict:
        """Lift the base by mm (negative: lower it), mm one of manual.JOG_STEPS_MM."""
        return self._machine(self._manual.jog, mm)

    def goto_level(self, level_mm: float) -> dict:
        return self._machine(self._manual.goto, level_mm)

    def _bench_taken(self) -> bool:
        return bool(
            (self._thread is not None and self._thread.is_alive())
            or (self._calibration is not None and self._calibration.active)
            or self._commissioning.holds_bench
        )

    def _machine(self, action, *args) -> dict:
        with self._lock:
            if self._thread is not None and self._thread.is_alive():
                raise DeviceError(
                    "stage",
                    f"a scan is running ({self._state['job_id']}); the panel's "
                    "controls wait until it has finished",
                )
            if self._calibration is not None and self._calibration.active:
                raise DeviceError("stage", "a guided calibration holds the bench; finish or cancel it first")
            if self._commissioning.holds_bench:
                raise DeviceError(
                    "stage",
                    f"the commissioning step {self._commissioning.session.step!r} "
                    "holds the bench; finish or cancel it first",
                )
        try:
            return action(*args)
        except DeviceError as e:
            self._note_fault(f"{e.where}: {e.problem}")
            raise

    def _open_for_panel(self):
        return self.factory.open(self.settings(), self._calibration_params())

    def _manual_report(self, status, hardware):
        with self._lock:
            changes = {}
            if status is not None:
                changes["manual"] = status
            if hardware:
                changes["hardware"] = {**self._state["hardware"], **hardware}
            if changes:
                self._set(**changes)

    # -- the job manager -----------------------------------------------------------------
    def rename_job(self, job_id: str, name: str) -> dict:
        name = " ".join(str(name or "").split())[:80]
        if not name:
            raise SettingError("name", "a job needs a name (1 to 80 characters)")
        self.store.get_job(job_id)
        self.store.update_job(job_id, name=name)
        self.store.event(job_id, "renamed", f"renamed {name!r}")
        return self.job(job_id)

    def delete_job(self, job_id: str) -> None:
        """The job's record and its whole folder (scan, outputs). Not while it runs."""
        with self._lock:
            job = self.store.get_job(job_id)
            ours = self._thread is not None and self._thread.is_alive() and self._state["job_id"] == job_id
            if ours and job["status"] not in ACTIVE:
                self._thread.join(timeout=5)  # the job is over; its thread is closing up
            if (
                ours
                and self._thread.is_alive()
                or job["status"] in ACTIVE
                and self._state["job_id"] == job_id
            ):
                raise DeviceError("job", f"job {job_id} is {job['status']}; stop it first")
            self.store.delete_job(job_id)
            shutil.rmtree(self.store.job_dir(job_id), ignore_errors=True)
            self._sizes.pop(job_id, None)
            if self._state["job_id"] == job_id:
                self._set(
                    job_id=None, state="idle", message="ready", levels_done=0, levels_total=0, eta_s=None
                )
        log.info("job %s deleted", job_id)

    def reprocess(self, job_id: str, changes: dict | None = None) -> str:
        """Process a kept scan again with other settings (the job's own, changed by `changes`);
        the job's outputs are replaced. Returns the job id at once, like import_scan."""
        changes = dict(changes or {})
        for key in changes:
            if key not in S.DEFAULTS:
                raise SettingError(key, "unknown setting")
        with self._lock:
            self._refuse_if_busy()
            job = self.store.get_job(job_id)
            if job["status"] in ACTIVE:
                raise DeviceError("job", f"job {job_id} is {job['status']}; stop it first")
            if not (self.store.job_dir(job_id) / "scan" / "scan.json").is_file():
                raise SettingError("job", f"job {job_id} kept no scan to process")
            settings = S.validate(S.full(job["settings"]), changes)
            self.store.update_job(
                job_id, status="processing", settings=settings, reason="", finished=None, interrupted=0
            )
            self.store.event(job_id, "reprocess", "processed again" + (f" with {changes}" if changes else ""))
            self._sizes.pop(job_id, None)
            self._launch_import(job_id)
            return job_id

    def repost(self, job_id: str, options: dict | None = None) -> list[str]:
        """Post the job again from its height map for another cutter, material, scallop or dialect
        (repost.py; no rescan). Returns the new files' names, which join the job's outputs."""
        from . import repost as R

        with self._lock:
            job = self.store.get_job(job_id)
            if job["status"] in ACTIVE:
                raise DeviceError("job", f"job {job_id} is {job['status']}; wait for it to finish")
        names = R.repost(self.store.job_dir(job_id), job_id, S.full(job["settings"]), options or {})
        with self._lock:
            job = self.store.get_job(job_id)
            self.store.update_job(job_id, outputs=sorted(set(job.get("outputs") or []) | set(names)))
            self.store.event(
                job_id, "reposted", "posted again: " + ", ".join(n for n in names if n.endswith(".nc"))
            )
            self._sizes.pop(job_id, None)
        return names

    def job_sizes(self) -> dict[str, int]:
        """Bytes on disk per job (its folder), counted once per finished job."""
        out = {}
        for job in self.store.list_jobs():
            key = (job["status"], job["finished"])
            hit = self._sizes.get(job["id"])
            if hit is None or hit[0] != key or job["status"] in ACTIVE:
                hit = (key, _folder_bytes(self.store.job_dir(job["id"])))
                self._sizes[job["id"]] = hit
            out[job["id"]] = hit[1]
        return out

    # -- commissioning (commissioning.py) ------------------------------------------------
    def commissioning(self) -> dict:
        """Every step's result in force with its date, the step in progress, the last ink change."""
        return self._commissioning.describe()

    def commission(self, step: str, action: str, values: dict | None = None) -> dict:
        """One action of one commissioning step (docs/api/README.md); returns commissioning()."""
        if action == "start" and step in ("level_zero", "camera"):
            with self._lock:
                if self._thread is not None and self._thread.is_alive():
                    raise SettingError(
                        "commissioning",
                        f"a scan is running ({self._state['job_id']}); "
                        "start this step when it has finished, or cancel it",
                    )
                if self._calibration is not None and self._calibration.active:
                    raise SettingError(
                        "commissioning", "a guided calibration holds the bench; cancel it first"
                    )
        return self._commissioning.act(step, action, values)

    def export_commissioning(self) -> dict:
        return self._commissioning.export()

    def import_commissioning(self, doc: dict) -> dict:
        return self._commissioning.import_(doc)

    def ink_changed(self) -> dict:
        return self._commissioning.ink_changed()

    def _commissioning_hooks(self):
        service = self

        class Hooks:
            operator = self._panel.operator or HumanOperator()

            @staticmethod
            def open_devices():
                service._manual.close()  # the panel's session gives the devices back
                return service.factory.open(service.settings(), {})

            settings = staticmethod(self.settings)
            update_settings = staticmethod(self.update_settings)
            show_frame = staticmethod(self._show_frame)
            job = staticmethod(self.job)
            start_reference_scan = staticmethod(self._start_reference_scan)

            @staticmethod
            def say(message):
                service._set(message=message)

            @staticmethod
            def cancel_scan():
                service.cancel(reason="cancelled: the commissioning step was cancelled")

        return Hooks()

    def _start_reference_scan(self, changes: dict, params: dict) -> str:
        """A scan of a reference part, processed by reference_processor; params are not the
        factory's (the part on the base is whatever the operator was asked to put there)."""
        with self._lock:
            self._refuse_if_busy()
            settings = S.validate(self.settings(), changes)
            job_id = time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)
            total = LevelPlan(settings).estimate_total([])
            self.store.create_job(job_id, params["name"], settings, params, total)
            self._launch(job_id, total, 0)
            return job_id

    def _show_frame(self, jpeg: bytes, info: dict):
        with self._lock:
            self._frame = (jpeg, info)

    def import_scan(self, folder) -> str:
        """A scan folder from elsewhere (the web's upload) becomes a job and is processed.

        Checked and copied first (importing.py): a refused folder leaves no job and no files.
        Returns the job id at once; processing runs like a scan's (state processing -> done).
        """
        scan = importing.check(folder)
        with self._lock:
            self._refuse_if_busy()  # say so before copying a big folder
        job_id = time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)
        importing.copy_into(scan, self.store.job_dir(job_id))  # outside the lock: it may take seconds
        n = len(scan.frames)
        name = str(scan.extra.get("name") or "imported scan")[:80]
        with self._lock:
            try:
                self._refuse_if_busy()
                self.store.create_job(job_id, name, self.settings(), {"name": name, "imported": True}, n)
                self.store.update_job(job_id, status="processing", levels_done=n)
                self.store.event(job_id, "imported", f"scan folder imported ({n} frames)")
            except BaseException:
                shutil.rmtree(self.store.job_dir(job_id), ignore_errors=True)
                raise
            self._launch_import(job_id)
            return job_id

    def _launch_import(self, job_id):
        job = self.store.get_job(job_id)
        self._stop.clear()
        expected = self._times.processing_s(job["levels_total"])
        self._set(
            state="processing",
            job_id=job_id,
            level_mm=None,
            levels_done=job["levels_total"],
            levels_total=job["levels_total"],
            eta_s=None if expected is None else round(expected, 1),
            eta_processing_s=expected,
            message="processing the scan again"
            if not job["params"].get("imported")
            else "processing the imported scan",
        )
        self._thread = threading.Thread(
            target=self._run_import, args=(job_id,), name=f"import-{job_id}", daemon=True
        )
        self._thread.start()

    def _run_import(self, job_id):
        self._manual.close()
        job = self.store.get_job(job_id)
        try:
            self.store.update_job(job_id, status="processing")
            outputs = processing.run(self.processor, self.store, job_id, S.full(job["settings"]), self._stop)
            status, reason = "done", ""
        except Cancelled:
            status, reason, outputs = (
                "cancelled",
                getattr(self._stop, "reason", "cancelled by the operator"),
                None,
            )
        except InkSliceError as e:
            status, reason, outputs = "failed", str(e), None
        except Exception as e:  # a bug must still end the job cleanly
            log.exception("processing the imported job %s", job_id)
            status, reason, outputs = "failed", f"internal error: {type(e).__name__}: {e}", None
        fields = dict(status=status, reason=reason, finished=time.time(), interrupted=0)
        if outputs is not None:
            fields["outputs"] = outputs
        try:
            self.store.update_job(job_id, **fields)
            self.store.event(job_id, status, reason or "imported scan processed")
        except DiskFull as e:  # held in memory, written when there is room
            log.warning("job %s: %s", job_id, e)
        self._set(
            state=status, message=reason or "imported scan processed", eta_s=0 if status == "done" else None
        )

    # -- USB sticks: the daemon holds the exporter (hw/usb.py); the web asks it to copy --------
    def usb_sticks(self) -> list[dict]:
        """The USB sticks plugged in (hw.usb.Stick as JSON); none when USB export is off."""
        return [s.to_json() for s in self.usb.sticks()] if self.usb is not None else []

    def export_to_usb(
        self, job_id: str, name: str = PROGRAM, stick: str | None = None, release: bool = True
    ) -> dict:
        """Copy a file of a job onto a USB stick (`stick`: its id; None: the first), read back and
        verified; with `release` synced and unmounted after. Returns hw.usb.CopyResult as JSON."""
        if self.usb is None:
            raise DeviceError("usb", "USB export is switched off on this box")
        path = self.job_file(job_id, name)
        return self.usb.export(path, stick, f"{job_id}-{name}", release=release).to_json()

    def latest_gcode(self) -> tuple[str, str] | None:
        """(job id, file name) of the newest finished job's finishing program (or, for a job
        without one, its first G-code file); None when no finished job has G-code."""
        for job in self.store.list_jobs(("done",)):  # newest first
            outputs = job["outputs"]
            name = (
                PROGRAM
                if PROGRAM in outputs
                else next((n for n in outputs if n.endswith(GCODE_SUFFIXES)), None)
            )
            if name:
                return job["id"], name
        return None

    def export_latest_gcode(self) -> dict:
        """What the long press does: the newest finished job's G-code onto the USB stick.

        Returns the outcome as a notice ({"code", "ok", "text", ...}; codes in notices.USB),
        which is also put on the display, in state()["notice"] and in the event log.
        Never raises for a missing stick or job: those are outcomes the operator reads.
        """
        if self.usb is None:
            return self._notify(usb_notice("off"))
        latest = self.latest_gcode()
        if latest is None:
            return self._notify(usb_notice("no_gcode"))
        self._notify(usb_notice("copying"), log_it=False)
        try:
            result = self.usb.export(self.job_file(*latest), None, "-".join(latest), release=True)
        except NoStick:
            return self._notify(usb_notice("no_stick"))
        except InkSliceError as e:
            return self._notify(usb_notice("failed", problem=e.problem))
        except Exception as e:  # an unexpected bug must still reach the operator
            log.exception("USB export")
            return self._notify(usb_notice("failed", problem=f"{type(e).__name__}: {e}"))
        if not result.safe_to_remove:  # copied and synced, but the unmount failed
            return self._notify(usb_notice("still_mounted", name=result.name, problem=result.unmount_problem))
        return self._notify(usb_notice("copied", name=result.name))

    # -- the system page: backup and restore, the box's figures ------------------------------
    def backup(self) -> dict:
        """The settings and the calibration history as one document (backup.py)."""
        return backups.backup(self.store)

    def restore(self, doc: dict) -> dict:
        """Replace the settings and calibration history by a backup's; refused while the bench works."""
        with self._lock:
            self._refuse_if_busy()
            if self._commissioning.session is not None:
                raise SettingError(
                    "restore", "a commissioning step is in progress; finish or cancel it first"
                )
            out = backups.restore(self.store, doc)
        self._set(message="settings and calibration restored from a backup")
        return out

    def test_webhook(self) -> dict:
        """POST a test message to the webhook setting's address now; {"ok", "problem"}."""
        return self.webhook.test()

    def system(self) -> dict:
        usage = shutil.disk_usage(self.data_dir)
        from .. import __version__

        return {
            "version": __version__,
            "daemon_started": self._started,
            "daemon_uptime_s": round(time.time() - self._started, 1),
            "box_uptime_s": _box_uptime(),
            "disk": {"path": str(self.data_dir), "total_bytes": usage.total, "free_bytes": usage.free},
            "jobs": len(self.store.list_jobs()),
            "webhook": self.webhook.last(),
        }

    def close(self) -> None:
        self.cancel(reason="cancelled: the daemon was stopped (service stop or shutdown)")
        self._manual.close()
        if self._calibration is not None:
            self._calibration.close()
        self._commissioning.close()
        self._closing.set()
        self._panel_thread.join(timeout=5)
        if self._usb_thread is not None:
            self._usb_thread.join(timeout=30)  # let a copy finish its fsync and verification
        self._panel.close()
        self.store.close()

    # == health (for the systemd watchdog) ==========================================
    def healthy(self) -> bool:
        try:
            self.store.list_jobs(("none",))
        except Exception:
            return False
        return self._panel_thread.is_alive()

    # == internals ================================================================
    def _refuse_if_busy(self):
        try:
            self.store.flush_unwritten()  # what a full disk held back is written first
        except DiskFull:
            held = ", ".join(f"job {k} ({v['status']})" for k, v in self.store.unwritten().items())
            raise DeviceError(
                "disk",
                f"full: the end of {held or 'the last job'} is not yet stored; free some "
                "space (delete old jobs), then start or resume",
            ) from None
        if self._calibration is not None and self._calibration.active:
            raise SettingError(
                "scan",
                "a guided calibration holds the bench; finish it or cancel it "
                "(the Calibrate page, or POST /api/calibration/cancel)",
            )
        if self._commissioning.holds_bench:
            step = self._commissioning.session.step
            raise SettingError(
                "scan",
                f"the commissioning step {step!r} holds the bench; finish it or cancel "
                f"it (POST /api/commissioning/{step}/cancel)",
            )
        current = self._state["job_id"]
        if (
            self._thread is not None
            and self._thread.is_alive()
            and current
            and self.store.get_job(current)["status"] in ("done", "failed", "cancelled")
        ):
            self._thread.join(timeout=5)  # the job is over; its thread is closing the devices
        if self._thread is not None and self._thread.is_alive():
            raise SettingError(
                "scan", f"a scan is already running ({self._state['job_id']}); cancel it first"
            )

    def _set(self, **changes):
        with self._lock:
            before = self._state["state"]
            self._state.update(changes)
            snap = copy.deepcopy(self._state)
            subs = list(self._subscribers)
        if before in ACTIVE and snap["state"] in ("done", "failed"):
            self._job_ended(snap)
        for q in subs:
            try:
                q.put_nowait(snap)
            except queue.Full:  # a stalled client loses updates, never blocks us
                pass

    def _launch(self, job_id, total, done):
        self._stop.clear()
        self._frame = None
        self._set(
            state="homing",
            job_id=job_id,
            level_mm=None,
            levels_done=done,
            levels_total=total,
            eta_s=None,
            message="starting",
        )
        self._thread = threading.Thread(
            target=self._run_job, args=(job_id,), name=f"scan-{job_id}", daemon=True
        )
        self._thread.start()

    def _run_job(self, job_id):
        self._manual.close()  # a panel session gives the stage and camera back
        job = self.store.get_job(job_id)
        self._job_settings = job["settings"]
        try:
            devices = self.factory.open(job["settings"], job["params"])
        except Exception as e:  # missing stage or camera, a bad wiring file ...
            reason = f"cannot start: {e}"
            self._note_fault(str(e))
            try:
                self.store.update_job(job_id, status="failed", reason=reason, finished=time.time())
                self.store.event(job_id, "failed", reason)
            except DiskFull as full:  # held in memory, written when there is room
                log.warning("job %s: %s", job_id, full)
            self._set(state="failed", message=reason)
            return
        self._set(hardware={**self._state["hardware"], **devices.hardware})
        self._devices = devices
        final = {}
        clock = _JobClock(self._times, fresh=job["levels_done"] == 0)

        def report(**changes):
            # the final state is published once the devices are closed, so a client that
            # sees "done" can start the next scan at once
            if changes.get("state") in ("done", "failed", "cancelled"):
                final.update(changes)
                if changes["state"] == "done":
                    clock.finished(job_id, self._state["levels_done"])
            else:
                with self._lock:
                    self._set(**clock.eta({**self._state, **changes}, changes))

        processor = self.processor
        if job["params"].get("reference"):  # the meniscus step's scan of the reference ball
            processor = reference_processor(job["params"]["reference"])
        try:
            runner = ScanRunner(
                self.store,
                job_id,
                devices,
                processor,
                report,
                self._stop,
                on_frame=self._keep_frame,
                disk_free_mb=self.disk_free_mb,
            )
            status = runner.run()
            if status == "failed":
                self._note_fault(self.store.get_job(job_id)["reason"])
        finally:
            with self._lock:
                self._devices = None
            devices.close()
            self._set(**final)

    def _job_ended(self, st):
        """A job just finished or failed: the webhook hears of it (a cancel was someone's choice)."""
        try:
            job = self.store.get_job(st["job_id"]) if st["job_id"] else None
        except InkSliceError:
            job = None
        if job is not None and job["params"].get("reference"):
            return  # commissioning's own scan: the page follows it
        event = "finished" if st["state"] == "done" else "failed"
        text = (
            f"{(job or {}).get('name') or 'the job'} is done"
            if event == "finished"
            else (job or {}).get("reason") or st.get("message") or "the job failed"
        )
        self.webhook.send(event, job, text)

    def _note_fault(self, reason):
        """A device's fault on its chip: "stage fake: no reply" -> stage: "fault: no reply"."""
        reason = reason.removeprefix("cannot start: ")
        for name in ("stage", "camera", "disk", "light", "bench"):
            if reason.startswith(name):
                problem = reason.partition(": ")[2] or reason
                self._set(hardware={**self._state["hardware"], name: f"fault: {problem}"})

    def _keep_frame(self, image: np.ndarray, info: dict):
        """The preview for latest_frame(): downscaled, the waterline drawn in red."""
        h, w = image.shape[:2]
        width = min(w, int(self._job_settings.get("preview_width", S.DEFAULTS["preview_width"])))
        small = cv2.resize(image, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)
        if small.ndim == 2:
            small = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
        part = info.pop("part")  # the runner's part mask (vision/part.py)
        mask = cv2.resize(
            part.astype(np.uint8), (small.shape[1], small.shape[0]), interpolation=cv2.INTER_NEAREST
        )
        contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(small, contours, -1, (0, 0, 255), 2, cv2.LINE_AA)
        ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 80])
        if ok:
            with self._lock:
                self._frame = (buf.tobytes(), {**info, "waterline": bool(contours)})
        self._grow_live_map(part, info.get("level_mm"))

    def _grow_live_map(self, part, level_mm):
        """The dashboard's height map so far; a preview must never fail the scan."""
        job_id = self._state["job_id"]
        try:
            live = self._live
            if live is None or live[0] != job_id:
                live = (job_id, LiveMap(load_scan(self.store.job_dir(job_id) / "scan").camera))
            if level_mm is not None:
                live[1].add(part, float(level_mm))
            with self._lock:
                self._live = live
        except Exception as e:
            log.warning("live height map: %s", e)

    # -- the front panel: button, LED, display ---------------------------------------
    def _open_panel(self) -> Devices:
        try:
            panel = self.factory.open_panel()
        except InkSliceError as e:
            log.warning("front panel unavailable: %s", e)
            panel = Devices(None, None, hardware={"panel": f"fault: {e}"})
        for name, status in panel.hardware.items():
            if status != "ok":
                log.warning("%s: %s (carrying on without it)", name, status)  # reported once
        self._state["hardware"].update(panel.hardware)
        return panel

    def _panel_loop(self, interval):
        tick = 0
        last_lines = None
        while not self._closing.wait(interval):
            tick += 1
            try:
                self._poll_button()
                st = self.state()
                self._drive_led(st, tick)
                lines = (
                    self._notice_lines()
                    or self._commissioning_lines(st)
                    or self._password_lines(st)
                    or self._display_lines(st)
                )
                if lines != last_lines and self._panel.display is not None:
                    self._panel.display.show(lines)
                    last_lines = lines
            except Exception as e:  # a flaky I2C bus must not kill the panel
                log.warning("front panel: %s", e)

    def _notify(self, notice: dict, log_it: bool = True) -> dict:
        """A front-panel outcome: on the display for NOTICE_S, in the state, in the event log."""
        lines = notice.pop("lines")
        with self._lock:
            self._shown_notice = (time.monotonic() + NOTICE_S, lines)
        self._set(notice=notice)
        if log_it:
            (log.info if notice.get("ok", True) else log.warning)("button: %s", notice["text"])
            self.store.event(None, notice["kind"], notice["text"])
        return notice

    def _start_usb_export(self):
        if self._usb_thread is not None and self._usb_thread.is_alive():
            self._notify(usb_notice("busy"), log_it=False)
            return
        log.info("button: long press, copying the latest G-code to the USB stick")
        self._usb_thread = threading.Thread(target=self.export_latest_gcode, name="inkslice-usb", daemon=True)
        self._usb_thread.start()

    def _poll_button(self):
        press = self._panel.button.poll() if self._panel.button is not None else None
        if not press:
            return
        if press == "long":
            self._start_usb_export()
            return
        with self._lock:
            self._shown_notice = None  # any short press gives the display back to the scan
        if self._thread is not None and self._thread.is_alive():
            log.info("button: cancelling the scan")
            threading.Thread(target=self.cancel, daemon=True).start()
        else:
            log.info("button: starting a scan with the current settings")
            self.start_scan({"name": "started at the bench"})

    def _drive_led(self, st, tick):
        if self._panel.led is None:
            return
        s = st["state"]
        # steady on while working, slow blink when failed, off otherwise
        on = s in ACTIVE or (s == "failed" and tick % 4 < 2)
        self._panel.led.set(on)

    def _notice_lines(self) -> list[str] | None:
        with self._lock:
            shown = self._shown_notice
            if shown is None:
                return None
            if time.monotonic() > shown[0]:
                self._shown_notice = None
                return None
        return [*shown[1], lan_address()]

    def _commissioning_lines(self, st) -> list[str] | None:
        """What a commissioning step asks of the person at the bench; a scan's progress (the
        reference ball's) takes the screen while it runs."""
        session = self._commissioning.session
        if session is None or st["state"] in ACTIVE:
            return None
        return [*session.display_lines(), lan_address()]

    def _password_lines(self, st) -> list[str] | None:
        """The first-run password (firstrun.py) while nobody has logged in; a scan's
        progress takes the screen while it runs."""
        if st["state"] in ACTIVE:
            return None
        password = self._first_run.pending()
        if not password:
            return None
        return ["FIRST LOGIN", "admin password:", password, lan_address()]

    @staticmethod
    def _display_lines(st) -> list[str]:
        level = f"level {st['level_mm']:.2f} mm" if st["level_mm"] is not None else ""
        progress = f"{st['levels_done']}/{st['levels_total']}" if st["levels_total"] else ""
        if st["eta_s"]:
            progress += f"  {int(st['eta_s']) // 60}:{int(st['eta_s']) % 60:02d} left"
        return [st["state"].upper(), level, progress, lan_address()]


class _JobClock:
    """A scan's ETA, scanning plus processing (eta.py), and its times once it ends done."""

    def __init__(self, times: JobTimes, fresh: bool, clock=time.monotonic):
        self.times, self.fresh, self.clock = times, fresh, clock
        self.t0 = clock()
        self.t_proc = None
        self.per_level = times.per_level_s()

    def eta(self, state: dict, changes: dict) -> dict:
        """`changes` with eta_s (and eta_processing_s) made to cover what is left of the whole job."""
        out = dict(changes)
        total, done = int(state.get("levels_total") or 0), int(state.get("levels_done") or 0)
        proc = self.times.processing_s(total)
        if state.get("state") == "processing":
            if self.t_proc is None:
                self.t_proc = self.clock()
                out["eta_s"] = None if proc is None else round(proc, 1)
                out["eta_processing_s"] = out["eta_s"]
            return out
        if "eta_s" in changes or "levels_done" in changes or "state" in changes:
            scan = changes.get("eta_s")  # the runner's: levels left x its recent level time
            if scan is None and self.per_level is not None:
                scan = self.per_level * max(total - done, 0)
            out["eta_s"] = None if scan is None else round(scan + (proc or 0.0), 1)
            out["eta_processing_s"] = None if proc is None else round(proc, 1)
        return out

    def finished(self, job_id: str, levels: int):
        if self.fresh and self.t_proc is not None:  # a resumed scan's times are only part of one
            now = self.clock()
            self.times.record(job_id, levels, self.t_proc - self.t0, now - self.t_proc)


def _folder_bytes(folder: Path) -> int:
    total = 0
    for p in Path(folder).rglob("*"):
        try:
            if p.is_file() and not p.is_symlink():
                total += p.stat().st_size
        except OSError:
            pass
    return total
