"""BenchService: the daemon's public face. It implements facade.Bench (daemon/facade.py, the
one list of what the daemon offers, with each method's meaning); the web UI, the CLI and the
tests use only those methods, in-process or over the socket (rpc.BenchClient).

    service = BenchService(data_dir, factory)      # factory: devices.py / sim.fakes
    job_id = service.start_scan({"name": "mouse", "level_step_mm": 1.0})
    for state in service.subscribe(timeout=30): ...
    service.job(job_id)["outputs"]; service.job_file(job_id, "toolpath.gcode")

This module holds the state (`current`, guarded by `lock`; publish() sends every change to
subscribers and tells the webhook of a job that ended) and the facade's own methods. The rest is
done by small collaborators the service holds, each in a module of its own; the members they use
(lock, current, publish(), refuse_if_busy(), ...) are public, the rest of the web sees the facade:
    job_thread jobthread.py   the one thread that runs a job (a scan, or processing a kept scan)
    _bench     bench.py       who holds the bench; guided calibration, commissioning, machine panel
    _panel     panel.py       the front panel's thread: button, status light, display
    live_view  preview.py     the newest frame and the live height map, for the dashboard
    _usb       usbexport.py   which job file goes to a USB stick (hw/usb.py copies it)
    _jobs      jobs.py        the job manager: rename, delete, reprocess, repost, sizes

Device factories are injected so the same service drives the real bench, the simulated one
(firmware under simavr + virtual camera) or the in-memory fakes: a hw.base.BenchFactory.
"""

from __future__ import annotations

import copy
import logging
import queue
import secrets
import shutil
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import DeviceError, InkSliceError, SettingError
from . import backup as backups
from . import importing, system
from . import settings as S
from .bench import BenchSessions
from .eta import JobTimes
from .firstrun import Pending
from .jobs import JobManager
from .jobthread import JobThread
from .levels import LevelPlan
from .panel import FrontPanel, lan_address, open_panel
from .preview import Preview
from .processing import PROGRAM, child_process
from .recovery import recover
from .runner import free_mb
from .store import ACTIVE, DiskFull, Store
from .usbexport import UsbExport
from .webhook import Webhook

__all__ = ["BenchService", "STATES", "lan_address"]

log = logging.getLogger("inkslice.service")
STATES = ("idle", "homing", "scanning", "processing", "done", "failed", "cancelled")


def new_job_id() -> str:
    return time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)


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
        self.first_run = Pending(self.data_dir)  # the web's first-run password, until the first login
        self.live_view = Preview()
        self.lock = threading.RLock()
        self.current = {
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
        self._closing = threading.Event()
        self._started = time.time()
        self.webhook = Webhook(self.settings)
        self.interrupted = recover(self.store)
        if self.interrupted:
            self._report_interrupted(self.store.get_job(self.interrupted[0]))
        devices = open_panel(factory)
        self.current["hardware"].update(devices.hardware)
        self._panel = FrontPanel(self, devices, panel_interval_s)
        self._bench = BenchSessions(self, devices.operator)
        self.commissioner = self._bench.commissioning
        self.manual = self._bench.manual
        self._usb = UsbExport(usb, self.store, self.job_file, self._panel.notify)
        self._jobs = JobManager(self)
        self.job_thread = JobThread(self)
        self.job_times = JobTimes(self.data_dir)
        self._panel.start()
        if self.interrupted and self.settings()["auto_resume"]:
            self.resume(self.interrupted[0])

    def _report_interrupted(self, last: dict) -> None:
        self.current.update(
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

    @property
    def usb(self):
        """hw.usb.UsbExporter (sticks(), export()); None: no USB export."""
        return self._usb.exporter

    # == the facade ===============================================================
    def state(self) -> dict:
        with self.lock:
            return copy.deepcopy(self.current)

    def start_scan(self, params: dict) -> str:
        params = dict(params or {})
        extra = set(self.factory.extra_params) | {"name"}
        for key in params:
            if key not in S.DEFAULTS and key not in extra:
                raise SettingError(key, "unknown scan parameter")
        with self.lock:
            self.refuse_if_busy()
            settings = S.validate(self.settings(), {k: v for k, v in params.items() if k in S.DEFAULTS})
            extras = {k: v for k, v in params.items() if k not in S.DEFAULTS}
            extras = self.factory.check(extras) or extras  # may fill in defaults (the surface)
            extras["name"] = str(params.get("name", ""))[:80]
            return self._create_scan_job(extras["name"], settings, extras)

    def cancel(self, wait_s: float = 30.0, reason: str = "cancelled by the operator") -> None:
        self._bench.cancel(wait_s)  # a calibration or commissioning step gives the bench back
        self.job_thread.cancel(reason, wait_s)

    def resume(self, job_id: str) -> str:
        with self.lock:
            self.refuse_if_busy()
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
                self.job_thread.start_processing(job_id)  # nothing to capture: process it again
            else:
                self.job_thread.start_scan(job_id, job["levels_total"], job["levels_done"])
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
        return self.live_view.latest()

    def settings(self) -> dict:
        return S.full(self.store.load_settings())

    def update_settings(self, changes: dict) -> dict:
        with self.lock:
            new = S.validate(self.settings(), changes)
            self.store.save_settings({k: new[k] for k in changes})
            return new

    def subscribe(self, timeout: float = 30.0):
        """Yields the state dict now and on every change, for at most `timeout` seconds."""
        q: queue.Queue = queue.Queue(maxsize=200)
        with self.lock:
            self._subscribers.append(q)
            first = copy.deepcopy(self.current)
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
            with self.lock:
                self._subscribers.remove(q)

    def events(self, job_id=None, limit=200) -> list[dict]:
        return self.store.events(job_id, limit)

    # == the extras the web UI offers ===============================================
    def live_heightmap(self) -> dict | None:
        return self.live_view.heightmap()

    def calibration(self) -> dict:
        return self._bench.guided().describe()

    def calibrate(self, step: str) -> dict:
        return self._bench.calibrate(step)

    def cancel_calibration(self, wait_s: float = 30.0) -> dict:
        return self._bench.cancel_calibration(wait_s)

    # -- the machine panel (manual.py, bench.py) ---------------------------------------------
    def preview(self) -> dict:
        return self._bench.preview()

    def home_stage(self) -> dict:
        return self._bench.machine(self.manual.home)

    def jog(self, mm: float) -> dict:
        return self._bench.machine(self.manual.jog, mm)

    def goto_level(self, level_mm: float) -> dict:
        return self._bench.machine(self.manual.goto, level_mm)

    # -- the job manager (jobs.py) -----------------------------------------------------------
    def rename_job(self, job_id: str, name: str) -> dict:
        return self._jobs.rename(job_id, name)

    def delete_job(self, job_id: str) -> None:
        self._jobs.delete(job_id)

    def reprocess(self, job_id: str, changes: dict | None = None) -> str:
        return self._jobs.reprocess(job_id, changes)

    def repost(self, job_id: str, options: dict | None = None) -> list[str]:
        return self._jobs.repost(job_id, options)

    def job_sizes(self) -> dict[str, int]:
        return self._jobs.sizes()

    # -- commissioning (commissioning.py) ----------------------------------------------------
    def commissioning(self) -> dict:
        return self.commissioner.describe()

    def commission(self, step: str, action: str, values: dict | None = None) -> dict:
        return self._bench.commission(step, action, values)

    def export_commissioning(self) -> dict:
        return self.commissioner.export()

    def import_commissioning(self, doc: dict) -> dict:
        return self.commissioner.import_(doc)

    def ink_changed(self) -> dict:
        return self.commissioner.ink_changed()

    def start_reference_scan(self, changes: dict, params: dict) -> str:
        """A scan of a reference part, processed by reference_processor; params are not the
        factory's (the part on the base is whatever the operator was asked to put there)."""
        with self.lock:
            self.refuse_if_busy()
            return self._create_scan_job(params["name"], S.validate(self.settings(), changes), params)

    def show_frame(self, jpeg: bytes, info: dict):
        self.live_view.show(jpeg, info)

    def import_scan(self, folder) -> str:
        """A scan folder from elsewhere (the web's upload) becomes a job and is processed.

        Checked and copied first (importing.py): a refused folder leaves no job and no files.
        Returns the job id at once; processing runs like a scan's (state processing -> done).
        """
        scan = importing.check(folder)
        with self.lock:
            self.refuse_if_busy()  # say so before copying a big folder
        job_id = new_job_id()
        importing.copy_into(scan, self.store.job_dir(job_id))  # outside the lock: it may take seconds
        n = len(scan.frames)
        name = str(scan.extra.get("name") or "imported scan")[:80]
        with self.lock:
            try:
                self.refuse_if_busy()
                self.store.create_job(job_id, name, self.settings(), {"name": name, "imported": True}, n)
                self.store.update_job(job_id, status="processing", levels_done=n)
                self.store.event(job_id, "imported", f"scan folder imported ({n} frames)")
            except BaseException:
                shutil.rmtree(self.store.job_dir(job_id), ignore_errors=True)
                raise
            self.job_thread.start_processing(job_id)
            return job_id

    # -- USB sticks: the daemon picks the job's file (usbexport.py), hw/usb.py copies it -------
    def usb_sticks(self) -> list[dict]:
        return self._usb.sticks()

    def export_to_usb(
        self, job_id: str, name: str = PROGRAM, stick: str | None = None, release: bool = True
    ) -> dict:
        return self._usb.export(job_id, name, stick, release)

    def latest_gcode(self) -> tuple[str, str] | None:
        return self._usb.latest_gcode()

    def export_latest_gcode(self) -> dict:
        return self._usb.export_latest()

    # -- the system page: backup and restore, the box's figures ------------------------------
    def backup(self) -> dict:
        """The settings and the calibration history as one document (backup.py)."""
        return backups.backup(self.store)

    def restore(self, doc: dict) -> dict:
        """Replace the settings and calibration history by a backup's; refused while the bench works."""
        with self.lock:
            self.refuse_if_busy()
            if self.commissioner.session is not None:
                raise SettingError(
                    "restore", "a commissioning step is in progress; finish or cancel it first"
                )
            out = backups.restore(self.store, doc)
        self.publish(message="settings and calibration restored from a backup")
        return out

    def test_webhook(self) -> dict:
        """POST a test message to the webhook setting's address now; {"ok", "problem"}."""
        return self.webhook.test()

    def system(self) -> dict:
        return system.figures(self.data_dir, self._started, len(self.store.list_jobs()), self.webhook.last())

    def close(self) -> None:
        self.cancel(reason="cancelled: the daemon was stopped (service stop or shutdown)")
        self._bench.close()
        self._closing.set()
        self._panel.close()
        self.store.close()

    # == health (for the systemd watchdog) ==========================================
    def healthy(self) -> bool:
        try:
            self.store.list_jobs(("none",))
        except Exception:
            return False
        return self._panel.alive()

    def scan_running(self) -> bool:
        """A scan's (or a kept scan's processing) thread is alive."""
        return self.job_thread.running()

    # == internals ================================================================
    def refuse_if_busy(self):
        try:
            self.store.flush_unwritten()  # what a full disk held back is written first
        except DiskFull:
            held = ", ".join(f"job {k} ({v['status']})" for k, v in self.store.unwritten().items())
            raise DeviceError(
                "disk",
                f"full: the end of {held or 'the last job'} is not yet stored; free some "
                "space (delete old jobs), then start or resume",
            ) from None
        self._bench.refuse_if_held("scan", scan=False)
        self.job_thread.join_if_over(self.current["job_id"])
        if self.job_thread.running():
            raise SettingError(
                "scan", f"a scan is already running ({self.current['job_id']}); cancel it first"
            )

    def publish(self, **changes):
        with self.lock:
            before = self.current["state"]
            self.current.update(changes)
            snap = copy.deepcopy(self.current)
            subs = list(self._subscribers)
        if before in ACTIVE and snap["state"] in ("done", "failed"):
            self._job_ended(snap)
        for q in subs:
            try:
                q.put_nowait(snap)
            except queue.Full:  # a stalled client loses updates, never blocks us
                pass

    def _create_scan_job(self, name: str, settings: dict, params: dict) -> str:
        job_id = new_job_id()
        total = LevelPlan(settings).estimate_total([])
        self.store.create_job(job_id, name, settings, params, total)
        self.job_thread.start_scan(job_id, total, 0)
        return job_id

    def _job_ended(self, st):
        try:
            job = self.store.get_job(st["job_id"]) if st["job_id"] else None
        except InkSliceError:
            job = None
        self.webhook.job_ended(job, st)

    def note_fault(self, reason):
        """A device's fault on its chip: "stage fake: no reply" -> stage: "fault: no reply"."""
        reason = reason.removeprefix("cannot start: ")
        for name in ("stage", "camera", "disk", "light", "bench"):
            if reason.startswith(name):
                problem = reason.partition(": ")[2] or reason
                self.publish(hardware={**self.current["hardware"], name: f"fault: {problem}"})

    def keep_frame(self, image: np.ndarray, info: dict):
        """The runner's frame: the preview for latest_frame() and the live height map."""
        width = self.job_thread.job_settings.get("preview_width", S.DEFAULTS["preview_width"])
        job_id = self.current["job_id"]
        self.live_view.keep(image, info, job_id, self.store.job_dir(job_id), width)
