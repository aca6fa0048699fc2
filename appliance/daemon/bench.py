"""Who holds the bench, and the sessions besides a scan that take it: the guided calibration,
a commissioning step and the machine panel.

Why one place: the stage and camera have one owner at a time. A scan's thread, a guided
calibration between "home" and "accept", a commissioning step that moves the stage, and the
machine panel's session (manual.py) each open the devices; every one of them asks holder() before
it starts and says in the same words who is in the way. The machine panel gives the devices back
at once when another asks (its session only keeps the light on for someone watching).

BenchSessions(service) uses of the service: store, factory, settings(), update_settings(), job(),
cancel(), scan_running(), lock, current, publish(), show_frame(), note_fault(),
start_reference_scan().
"""

from __future__ import annotations

from ..errors import DeviceError, InkSliceError, SettingError
from ..hw.base import HumanOperator
from .calibration import GuidedCalibration
from .commissioning import Commissioning
from .manual import ManualSession

CANCEL_HINT = {
    "calibration": "(the Calibrate page, or POST /api/calibration/cancel)",
    "commissioning": "(POST /api/commissioning/{step}/cancel)",
}


class BenchSessions:
    def __init__(self, service, operator):
        self.service = service
        self.operator = operator
        self.calibration: GuidedCalibration | None = None
        self.commissioning = Commissioning(service.store, _CommissioningHooks(self))
        self.manual = ManualSession(
            self._open_for_panel, service.settings, service.show_frame, self._manual_report
        )

    # -- who holds the bench -----------------------------------------------------------------
    def holder(self, scan: bool = True, calibration: bool = True) -> str | None:
        """Who holds the bench, in words ("a scan is running (ID)", ...); None when it is free.
        The machine panel never counts: it gives the devices back to whoever asks."""
        svc = self.service
        if scan and svc.scan_running():
            return f"a scan is running ({svc.current['job_id']})"
        if calibration and self.calibration is not None and self.calibration.active:
            return "a guided calibration holds the bench"
        if self.commissioning.holds_bench:
            return f"the commissioning step {self.commissioning.session.step!r} holds the bench"
        return None

    def refuse_if_held(self, where: str, scan=True, calibration=True, error=SettingError) -> None:
        """Raise `error(where, "<holder>; finish or cancel it first ...")` when someone holds it."""
        held = self.holder(scan, calibration)
        if held is None:
            return
        if held.startswith("a scan"):
            raise error(where, f"{held}; wait until it has finished, or cancel it")
        kind = "calibration" if "calibration" in held else "commissioning"
        step = self.commissioning.session.step if kind == "commissioning" else ""
        raise error(where, f"{held}; finish it or cancel it first {CANCEL_HINT[kind].format(step=step)}")

    def close(self) -> None:
        self.manual.close()
        if self.calibration is not None:
            self.calibration.close()
        self.commissioning.close()

    def cancel(self, wait_s: float) -> None:
        """A calibration or commissioning step left half-way gives the bench back."""
        if self.calibration is not None and self.calibration.active:
            self.cancel_calibration(wait_s)
        if self.commissioning.holds_bench:
            self.commissioning.cancel(wait_s=wait_s)

    def open_devices(self, params: dict | None = None):
        self.manual.close()  # the panel's session gives the devices back
        svc = self.service
        return svc.factory.open(svc.settings(), self.calibration_params() if params is None else params)

    def _open_for_panel(self):
        return self.service.factory.open(self.service.settings(), self.calibration_params())

    def calibration_params(self) -> dict:
        return self.service.factory.check({}) or {}  # the simulated bench fills in its part

    # -- the guided calibration (calibration.py) ---------------------------------------------
    def guided(self) -> GuidedCalibration:
        svc = self.service
        with svc.lock:
            if self.calibration is None:
                self.calibration = GuidedCalibration(
                    self.open_devices,
                    svc.store,
                    svc.settings(),
                    show_frame=svc.show_frame,
                    operator=self.operator,
                    **svc.factory.calibration_target,
                )
            return self.calibration

    def calibrate(self, step: str) -> dict:
        if step == "cancel":
            return self.cancel_calibration()
        svc = self.service
        cal = self.guided()
        with svc.lock:
            if svc.scan_running():
                raise SettingError(
                    "calibration", f"{self.holder()}; calibrate when it has finished, or cancel it"
                )
            if step == "home":  # one owner of the devices at a time
                self.refuse_if_held("calibration", scan=False, calibration=False)
        if not cal.lock.acquire(blocking=False):
            raise SettingError("calibration", "a calibration step is already running")
        try:
            cal.settings = svc.settings()
            svc.publish(message=f"calibration: {step}")
            try:
                out = cal.do(step)
            except InkSliceError as e:
                svc.publish(message=f"calibration: {step} failed: {e.problem}")
                raise
            done = not cal.active
            svc.publish(
                message="calibration stored" if done and step == "accept" else f"calibration: {step} done"
            )
            if step == "accept":
                svc.store.event(None, "calibrated", f"guided calibration stored: {cal.describe()}")
            return out
        finally:
            cal.lock.release()

    def cancel_calibration(self, wait_s: float = 30.0) -> dict:
        cal = self.calibration
        if cal is None:
            return self.guided().describe()
        cal.interrupt()  # a running step (homing, say) ends at once
        if not cal.lock.acquire(timeout=wait_s):
            raise SettingError("calibration", f"the running step did not stop within {wait_s:.0f} s")
        try:
            was_active = cal.active
            cal.close()
        finally:
            cal.lock.release()
        if was_active:
            self.service.publish(message="calibration cancelled")
            self.service.store.event(None, "calibration", "guided calibration cancelled; the bench is free")
        return cal.describe()

    # -- the machine panel (manual.py) -------------------------------------------------------
    def machine(self, action, *args) -> dict:
        """Run a machine-panel action unless a scan, calibration or commissioning holds the bench."""
        with self.service.lock:
            self.refuse_if_held("stage", error=DeviceError)
        try:
            return action(*args)
        except DeviceError as e:
            self.service.note_fault(f"{e.where}: {e.problem}")
            raise

    def preview(self) -> dict:
        """While another holds the bench, its own frames are the preview: the status says why the
        panel is closed ("busy") instead of refusing."""
        try:
            return self.machine(self.manual.preview)
        except DeviceError as e:
            if self.manual.active or self.holder() is None:
                raise
            return {**self.manual.status(), "busy": e.problem}

    def _manual_report(self, status, hardware) -> None:
        svc = self.service
        with svc.lock:
            changes = {}
            if status is not None:
                changes["manual"] = status
            if hardware:
                changes["hardware"] = {**svc.current["hardware"], **hardware}
            if changes:
                svc.publish(**changes)

    # -- commissioning (commissioning.py) ----------------------------------------------------
    def commission(self, step: str, action: str, values: dict | None) -> dict:
        if action == "start" and step in ("level_zero", "camera"):  # the steps that move the stage
            with self.service.lock:
                if self.service.scan_running():
                    raise SettingError(
                        "commissioning",
                        f"{self.holder()}; start this step when it has finished, or cancel it",
                    )
                if self.calibration is not None and self.calibration.active:
                    self.refuse_if_held("commissioning", scan=False)
        return self.commissioning.act(step, action, values)


class _CommissioningHooks:
    """What commissioning.py may ask of the daemon (commissioning.Hooks)."""

    def __init__(self, sessions: BenchSessions):
        svc = sessions.service
        self._sessions, self._service = sessions, svc
        self.operator = sessions.operator or HumanOperator()
        self.settings, self.update_settings, self.job = svc.settings, svc.update_settings, svc.job
        self.show_frame = svc.show_frame
        self.start_reference_scan = svc.start_reference_scan

    def open_devices(self):
        return self._sessions.open_devices({})

    def say(self, message: str) -> None:
        self._service.publish(message=message)

    def cancel_scan(self) -> None:
        self._service.cancel(reason="cancelled: the commissioning step was cancelled")
