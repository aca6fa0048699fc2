"""Commissioning: the measurements a box needs once (and again after an ink change), from the phone.

    level_zero  the stage position at which the base top meets the ink (= the setting
                level_at_home_mm): measured with the stage and the camera on the empty
                base, or entered
    camera      the lens (tilted views of the printed board) and the liquid plane (the board
                lying flat on the base at level zero)
    tank        the tank's inner area, for the ink's displacement: entered (width x depth)
    meniscus    the ink's capillary length and contact angle, from a scan of a reference part
                (a precision ball, 25.4 mm by default); the reference scan is then processed
                with the new model and its error against the ball kept ("this box measures
                the 25.4 mm ball to 0.02 mm")

Level zero comes first: the board of the camera step must lie on the liquid plane.

Every step is `start`ed, then driven by its own actions, and can be `cancel`led or
`skip`ped at any point: cancel stops the stage, closes the devices and asks for the base
to be cleared; nothing is stored. Only the level-zero and camera steps hold the bench's
devices between actions (the service refuses scans meanwhile and says how to cancel);
the meniscus step's reference scan is an ordinary scan job.

This module is the wizard: the step in progress and what it may do next. The results, and
which are in force, are commissioned.py's; the measurements themselves are measurements.py's.

What must be on the base is asked through the front panel's Operator (hw/base.py): on a
real box a message to the person, on the simulated bench the object placed.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field

import numpy as np

from ..errors import InkSliceError, SettingError
from ..hw.base import Placement
from ..vision.calibration import find_corners
from . import measurements as M
from .calibration import BOARD, show_board
from .calibration import board_details as _board_details
from .commissioned import (
    SHORT,
    STEPS,
    TITLES,
    check_export,
    date_text,
    export_doc,
    import_records,
    overview,
    public,
    stored_camera,
    summary,
)

# -- one step in progress -------------------------------------------------------------------


@dataclass
class Session:
    step: str
    stage: str  # where in the step: see ACTIONS
    prompt: str = ""
    detected: dict | None = None
    job_id: str | None = None
    error: str | None = None
    devices: object = None
    views: list = field(default_factory=list)  # the camera step's board views (frames)
    pending: dict | None = None  # the result waiting for "accept"
    placement: str | None = None  # what the operator was last asked to put on the base

    def display_lines(self) -> list[str]:
        """The front panel's four short lines (16 characters) while the step waits on the person."""
        what = {
            "empty": "EMPTY THE BASE",
            "board_views": "HOLD BOARD TILTD",
            "board_flat": "BOARD FLAT ON IT",
            "reference": "BALL ON THE BASE",
        }.get(self.placement, "")
        done = (
            f"{len(self.views)} views" if self.step == "camera" and self.stage == "views" else "see the phone"
        )
        return ["SETUP " + SHORT[self.step], what, done]

    def to_json(self, actions) -> dict:
        return {
            "step": self.step,
            "stage": self.stage,
            "prompt": self.prompt,
            "detected": dict(self.detected) if self.detected else None,
            "job_id": self.job_id,
            "error": self.error,
            "holds_bench": self.devices is not None,
            "actions": list(actions) + ["cancel", "skip"],
        }


# what each step accepts in each stage (besides cancel and skip)
ACTIONS = {
    ("level_zero", "ready"): ("measure",),
    ("level_zero", "check"): ("measure", "accept"),
    ("camera", "views"): ("view", "plane"),
    ("camera", "check"): ("view", "plane", "accept"),
    ("meniscus", "ready"): ("scan",),
    ("meniscus", "scanning"): (),
    ("meniscus", "check"): ("scan", "accept"),
    ("meniscus", "failed"): ("scan",),
}
IDLE_ACTIONS = {
    "level_zero": ("start", "enter"),
    "camera": ("start",),
    "tank": ("enter",),
    "meniscus": ("start",),
}


class Commissioning:
    """The steps' state and actions; BenchService owns one and gives it these hooks:

    open_devices()          the bench's devices (factory.open)
    operator                hw.base.Operator: asks for what must be on the base
    settings(), update_settings(changes)
    show_frame(jpeg, info)  the preview on the dashboard
    say(message)            the service's state message (display, web)
    start_reference_scan(settings_changes, params) -> job id; cancel_scan(); job(job_id)
    """

    def __init__(self, store, hooks):
        self.store, self.h = store, hooks
        self.session: Session | None = None
        self.lock = threading.Lock()  # one action at a time

    @property
    def holds_bench(self) -> bool:
        s = self.session
        return s is not None and s.devices is not None

    # -- reading --------------------------------------------------------------------
    def describe(self) -> dict:
        self._follow_reference_scan()
        steps, force = overview(self.store)
        for row in steps:
            row["actions"] = list(IDLE_ACTIONS[row["id"]]) + ["skip"]
        s = self.session
        return {
            "steps": steps,
            "active": s.to_json(ACTIONS.get((s.step, s.stage), ())) if s else None,
            "ink_changed": force["ink_changed"],
            "ink_changed_text": date_text(force["ink_changed"]),
            "board": M.board_to_print(),
            "reference": {"kind": "ball", "default_diameter_mm": M.BALL_MM},
        }

    # -- acting ---------------------------------------------------------------------
    def act(self, step: str, action: str, values: dict | None = None) -> dict:
        values = dict(values or {})
        if step not in STEPS:
            raise SettingError(
                "step", f"unknown commissioning step {step!r}; the steps are {', '.join(STEPS)}"
            )
        if action == "cancel":
            self.cancel(step)
            return self.describe()
        if action == "skip" and self.session is not None and self.session.step == step:
            self.cancel(step)  # skipping stops what the step runs (the ball's scan) first
        if not self.lock.acquire(blocking=False):
            raise SettingError(
                "commissioning", "a commissioning action is already running; wait, or cancel it"
            )
        try:
            self._follow_reference_scan()
            s = self.session
            if action == "skip":
                self._end(step, "skipped")
                self.store.add_calibration({"kind": step, "skipped": True})
                self.h.say(f"commissioning: {TITLES[step]} skipped")
                return self.describe()
            if s is not None and s.step != step:
                raise SettingError(
                    "commissioning",
                    f"the {TITLES[s.step].lower()} step is in progress; finish, skip or cancel it first",
                )
            allowed = ACTIONS.get((s.step, s.stage), ()) if s else IDLE_ACTIONS[step]
            if action not in allowed:
                raise SettingError(
                    "action",
                    f"{action!r} is not possible now in the {TITLES[step].lower()} step; "
                    f"possible: {', '.join(list(allowed) + ['cancel', 'skip'])}",
                )
            self.h.say(f"commissioning: {TITLES[step]}: {action}")
            try:
                getattr(self, f"_{step}_{action}")(values)
            except InkSliceError as e:
                if self.session is not None:
                    self.session.error = f"{e.where}: {e.problem}"
                self.h.say(f"commissioning: {TITLES[step]}: {action} failed: {e.problem}")
                raise
            if self.session is not None:
                self.session.error = None
            return self.describe()
        finally:
            self.lock.release()

    def cancel(self, step: str | None = None, wait_s: float = 30.0):
        """Stop the step in progress wherever it is: stage stopped, devices closed, the reference
        scan cancelled, the base to be cleared. Nothing is stored."""
        s = self.session
        if s is None or (step is not None and s.step != step):
            return
        self._interrupt()
        if not self.lock.acquire(timeout=wait_s):
            raise SettingError("commissioning", f"the running action did not stop within {wait_s:.0f} s")
        try:
            if s.job_id and self.h.job(s.job_id)["status"] in ("homing", "scanning", "processing"):
                self.h.cancel_scan()
            self._end(s.step, "cancelled")
            self.store.event(None, "commissioning", f"{TITLES[s.step]} cancelled; the bench is free")
            self.h.say(f"commissioning: {TITLES[s.step]} cancelled")
        finally:
            self.lock.release()

    def close(self):
        if self.session is not None:
            self._interrupt()
            self._close_devices(self.session)
            self.session = None

    def ink_changed(self) -> dict:
        self.store.add_calibration({"kind": "ink_changed"})
        self.store.event(
            None, "commissioning", "ink changed: the meniscus and level zero should be measured again"
        )
        return self.describe()

    # -- export and import ----------------------------------------------------------
    def export(self) -> dict:
        return export_doc(self.store)

    def import_(self, doc) -> dict:
        results = check_export(doc)
        if self.session is not None:
            raise SettingError(
                "commissioning",
                f"the {TITLES[self.session.step].lower()} step is in progress; "
                "finish or cancel it before importing",
            )
        import_records(self.store, doc, results)
        if "level_zero" in results:
            self._set_level_zero(float(results["level_zero"]["result"]["level_at_home_mm"]))
        self.store.event(None, "commissioning", f"commissioning imported: {', '.join(results) or 'nothing'}")
        return self.describe()

    # -- helpers ----------------------------------------------------------------------
    def _place(self, what, text, view=0, **details):
        request = Placement(what, text, details, view)
        self.h.operator.place(request)
        if self.session is not None:
            self.session.prompt, self.session.placement = text, what
        self.h.say(text)

    def _interrupt(self):
        s = self.session
        if s is not None and s.devices is not None and s.devices.stage is not None:
            try:
                s.devices.stage.stop()  # a running home, move or search ends at once
            except Exception:
                pass

    def _close_devices(self, s: Session):
        devices, s.devices = s.devices, None
        if devices is not None:
            devices.release()

    def _end(self, step, how):
        s = self.session
        if s is not None and s.step == step:
            self._close_devices(s)
            self.session = None
            self._place("clear", f"{TITLES[step]} {how}: take the board or the reference part off the base")

    def _open_and_home(self, s: Session):
        s.devices = self.h.open_devices()
        try:
            s.devices.stage.home()
        except BaseException:
            self._close_devices(s)
            raise

    def _frame(self, s: Session) -> np.ndarray:
        frame = s.devices.capture_lit()
        if frame is None or frame.ndim not in (2, 3):
            raise InkSliceError("camera", "returned no image")
        return frame

    def _preview(self, frame, corners=None):
        show_board(self.h.show_frame, frame, BOARD, corners, "commissioning")

    def _store(self, kind, result, method, **more):
        self.store.add_calibration({"kind": kind, "result": result, "method": method, **more})
        self.store.event(None, "commissioning", f"{TITLES[kind]} stored ({method}): {summary(kind, result)}")
        self.h.say(f"commissioning: {TITLES[kind]} stored: {summary(kind, result)}")

    def _set_level_zero(self, value):
        self.h.update_settings(M.level_zero_changes(self.h.settings(), value))

    # -- level zero -------------------------------------------------------------------
    def _level_zero_enter(self, values):
        value = M.positive_mm(values, "level_at_home_mm")
        self._end("level_zero", "entered")
        self._set_level_zero(value)
        self._store("level_zero", {"level_at_home_mm": round(value, 4)}, "entered")

    def _level_zero_start(self, values):
        s = self.session = Session("level_zero", "ready")
        self._place("empty", "Take everything off the base; the stage will find where its top meets the ink")
        try:
            self._open_and_home(s)
        except BaseException:
            self._end("level_zero", "could not start")
            raise

    def _level_zero_measure(self, values):
        s = self.session
        guess = float(self.h.settings()["level_at_home_mm"])
        stage = s.devices.stage

        def shows(pos):
            stage.move_to(pos)
            frame = self._frame(s)
            return M.base_shows(frame), frame

        value, frame = M.find_level_zero(shows, guess)
        self._preview(frame)
        s.pending = {"level_at_home_mm": value}
        s.detected = {
            "level_at_home_mm": value,
            "resolution_mm": M.LEVEL_RESOLUTION_MM,
            "setting_was_mm": guess,
        }
        s.stage = "check"
        stage.move_to(max(value - 5.0, 0.0))  # the base back under the ink

    def _level_zero_accept(self, values):
        value = self.session.pending["level_at_home_mm"]
        self._end("level_zero", "measured")
        self._set_level_zero(value)
        self._store("level_zero", {"level_at_home_mm": value}, "measured")

    # -- camera -----------------------------------------------------------------------
    def _camera_start(self, values):
        s = self.session = Session("camera", "views")
        try:
            self._open_and_home(s)
        except BaseException:
            self._end("camera", "could not start")
            raise
        self._ask_view(s)

    def _ask_view(self, s):
        self._place(
            "board_views",
            f"Hold the printed board ({BOARD.cols} x {BOARD.rows} inner corners, "
            f"{BOARD.square_mm:g} mm squares) tilted under the camera, a new angle each "
            f"view ({len(s.views)} of at least {M.MIN_VIEWS} taken), then take the view; "
            "or go on to the flat board",
            view=len(s.views),
            **_board_details(),
        )

    def _camera_view(self, values):
        s = self.session
        frame = self._frame(s)
        corners = find_corners(frame, BOARD, f"board view {len(s.views) + 1}")
        s.views.append(frame)
        self._preview(frame, corners)
        s.detected = {**(s.detected or {}), "views": len(s.views)}
        self._ask_view(s)

    def _camera_plane(self, values):
        s = self.session
        lens = M.lens_from_views(s.views, stored_camera(self.store))
        self._place(
            "board_flat",
            "Lay the board flat on the base, centred, its rows along the base's "
            "x side; the stage raises it to the ink line",
            **_board_details(),
        )
        s.devices.stage.move_to(float(self.h.settings()["level_at_home_mm"]))
        frame = self._frame(s)
        camera, report = M.plane_camera(frame, lens, len(s.views))
        s.pending = {"camera": camera, "report": report}
        s.detected = report
        s.stage = "check"
        self._preview(frame, M.board_corners(frame))

    def _camera_accept(self, values):
        pending = self.session.pending
        self._end("camera", "done")
        self._store("camera", pending["report"], "measured", camera=pending["camera"])

    # -- tank -------------------------------------------------------------------------
    def _tank_enter(self, values):
        self._store("tank", M.tank_result(values), "entered")

    # -- meniscus ---------------------------------------------------------------------
    def _meniscus_start(self, values):
        d = float(values.get("diameter_mm", M.BALL_MM))
        if not 5.0 <= d <= 60.0:
            raise SettingError("diameter_mm", f"a reference ball of {d} mm: use one of 5 to 60 mm")
        s = self.session = Session("meniscus", "ready")
        s.detected = {"diameter_mm": d}
        self._place(
            "reference",
            f"Put the {d:g} mm ball on the middle of the base, then start its scan",
            part="ball",
            diameter_mm=d,
        )

    def _meniscus_scan(self, values):
        s = self.session
        d = s.detected["diameter_mm"]
        changes = M.reference_scan_changes(d, float(values.get("level_step_mm", 0.5)))
        s.job_id = self.h.start_reference_scan(
            changes, {"name": f"reference: {d:g} mm ball", "reference": {"kind": "ball", "diameter_mm": d}}
        )
        s.stage, s.pending = "scanning", None

    def _follow_reference_scan(self):
        s = self.session
        if s is None or s.step != "meniscus" or s.stage != "scanning":
            return
        job = self.h.job(s.job_id)
        if job["status"] in ("homing", "scanning", "processing"):
            return
        if job["status"] == "done":
            path = self.store.job_dir(s.job_id) / "reference.json"
            s.pending = json.loads(path.read_text())
            s.detected = {"diameter_mm": s.detected["diameter_mm"], **public(s.pending)}
            s.stage = "check"
        else:
            s.stage, s.error = "failed", f"the reference scan {job['status']}: {job['reason']}"

    def _meniscus_accept(self, values):
        result = dict(self.session.pending)
        self._end("meniscus", "done")
        self._store("meniscus", result, "measured")
