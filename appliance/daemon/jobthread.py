"""The thread that runs a job, one at a time: a scan (runner.py: capture, then processing) or
the processing of a kept scan (an imported folder, a reprocess, a resumed import).

Why apart from the service: the service answers requests and publishes state; this module owns
what runs meanwhile: the thread, its stop event (a cancel sets it and stops the stage at once),
the devices a scan holds open, and the ETA clock (eta.py). Every change of state goes back
through the service's publish(), so subscribers, the webhook and the panel see it.

JobThread(service) uses of the service: store, factory, processor, disk_free_mb, lock, current,
publish(), job_times, manual, keep_frame(), note_fault(), live_view.
"""

from __future__ import annotations

import logging
import threading
import time

from ..errors import Cancelled, InkSliceError
from . import processing
from . import settings as S
from .eta import JobClock
from .measurements import reference_processor
from .runner import ScanRunner
from .store import DiskFull

log = logging.getLogger("inkslice.jobthread")
OVER = ("done", "failed", "cancelled")


class JobThread:
    def __init__(self, service):
        self.service = service
        self.store = service.store
        self.thread: threading.Thread | None = None
        self.stop = threading.Event()
        self.devices = None  # the scan's, while it holds them open
        self.job_settings: dict = {}

    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive()

    def join_if_over(self, job_id: str | None) -> None:
        """The job is over but its thread is still closing the devices: wait for that."""
        if self.running() and job_id and self.store.get_job(job_id)["status"] in OVER:
            self.thread.join(timeout=5)

    def cancel(self, reason: str, wait_s: float) -> None:
        svc = self.service
        with svc.lock:
            thread = self.thread
            if thread is None or not thread.is_alive():
                return
            self.stop.reason = reason
            self.stop.set()
            svc.publish(message="cancelling")
            devices = self.devices
        if devices is not None and devices.stage is not None:
            try:
                devices.stage.stop()  # preempts a long move or homing at once
            except Exception as e:
                log.warning("stop on cancel: %s", e)
        thread.join(timeout=wait_s)

    def start_scan(self, job_id, total, done):
        svc = self.service
        self.stop.clear()
        svc.live_view.clear()
        svc.publish(
            state="homing",
            job_id=job_id,
            level_mm=None,
            levels_done=done,
            levels_total=total,
            eta_s=None,
            message="starting",
        )
        self.thread = threading.Thread(
            target=self._run_scan, args=(job_id,), name=f"scan-{job_id}", daemon=True
        )
        self.thread.start()

    def _run_scan(self, job_id):
        svc = self.service
        svc.manual.close()  # a panel session gives the stage and camera back
        job = self.store.get_job(job_id)
        self.job_settings = job["settings"]
        try:
            devices = svc.factory.open(job["settings"], job["params"])
        except Exception as e:  # missing stage or camera, a bad wiring file ...
            reason = f"cannot start: {e}"
            svc.note_fault(str(e))
            try:
                self.store.update_job(job_id, status="failed", reason=reason, finished=time.time())
                self.store.event(job_id, "failed", reason)
            except DiskFull as full:  # held in memory, written when there is room
                log.warning("job %s: %s", job_id, full)
            svc.publish(state="failed", message=reason)
            return
        svc.publish(hardware={**svc.current["hardware"], **devices.hardware})
        self.devices = devices
        final = {}
        clock = JobClock(svc.job_times, fresh=job["levels_done"] == 0)

        def report(**changes):
            # the final state is published once the devices are closed, so a client that
            # sees "done" can start the next scan at once
            if changes.get("state") in ("done", "failed", "cancelled"):
                final.update(changes)
                if changes["state"] == "done":
                    clock.finished(job_id, svc.current["levels_done"])
            else:
                with svc.lock:
                    svc.publish(**clock.eta({**svc.current, **changes}, changes))

        processor = svc.processor
        if job["params"].get("reference"):  # the meniscus step's scan of the reference ball
            processor = reference_processor(job["params"]["reference"])
        try:
            runner = ScanRunner(
                self.store,
                job_id,
                devices,
                processor,
                report,
                self.stop,
                on_frame=svc.keep_frame,
                disk_free_mb=svc.disk_free_mb,
            )
            status = runner.run()
            if status == "failed":
                svc.note_fault(self.store.get_job(job_id)["reason"])
        finally:
            with svc.lock:
                self.devices = None
            devices.close()
            svc.publish(**final)

    def start_processing(self, job_id):
        svc = self.service
        job = self.store.get_job(job_id)
        self.stop.clear()
        expected = svc.job_times.processing_s(job["levels_total"])
        svc.publish(
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
        self.thread = threading.Thread(
            target=self._run_processing, args=(job_id,), name=f"import-{job_id}", daemon=True
        )
        self.thread.start()

    def _run_processing(self, job_id):
        svc = self.service
        svc.manual.close()  # a panel session gives the devices back
        job = self.store.get_job(job_id)
        try:
            self.store.update_job(job_id, status="processing")
            outputs = processing.run(svc.processor, self.store, job_id, S.full(job["settings"]), self.stop)
            status, reason = "done", ""
        except Cancelled:
            status, reason, outputs = (
                "cancelled",
                getattr(self.stop, "reason", "cancelled by the operator"),
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
        svc.publish(
            state=status, message=reason or "imported scan processed", eta_s=0 if status == "done" else None
        )
