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

Results go to the store's calibration table, each with its date: {"kind": step, "result":
{...}, "method": "measured" | "entered" | "imported"} (a camera result also carries the
"camera" block scan.json takes). The newest result of each kind is the one in force;
`ink_changed` records a date after which older meniscus and level-zero results are stale.
in_force()/scan_extra() are what the runner writes into every scan.json.

What must be on the base is asked through the front panel's Operator (hw/base.py): on a
real box a message to the person, on the simulated bench the object placed.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import Cancelled, InkSliceError, SettingError
from ..hw.base import Placement
from ..vision.calibration import Board, camera_json, find_corners, intrinsics, plane_homography
from ..vision.camera_block import read_camera
from ..vision.printboard import describe as print_instructions
from ..vision.printboard import printed_size_mm
from .calibration import BOARD, JIG
from .calibration import board_details as _board_details

FORMAT = "inkslice.commissioning/1"
STEPS = ("level_zero", "camera", "tank", "meniscus")
TITLES = {
    "level_zero": "Level zero",
    "camera": "Camera lens and liquid plane",
    "tank": "Tank area",
    "meniscus": "Meniscus (reference ball)",
}
SHORT = {"level_zero": "LEVEL 0", "camera": "CAMERA", "tank": "TANK", "meniscus": "MENISCUS"}
INK_SENSITIVE = ("level_zero", "meniscus")  # an ink change makes these stale
MIN_VIEWS = 3
LEVEL_SEARCH_MM = 12.0  # level zero is searched this far either side of the current setting
LEVEL_RESOLUTION_MM = 0.01
BASE_SHOWS = 0.25  # fraction of the frame the base top covers once it stands above the ink
BALL_MM = 25.4


def _date(t):
    return time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(t)) if t else None


# -- what is stored, and what is in force -------------------------------------------------


def _kind(record: dict) -> str | None:
    if "kind" in record:
        return record["kind"]
    return "camera" if "camera" in record else None  # a guided calibration's row (calibration.py)


def in_force(store) -> dict:
    """{kind: {"date", "result", "method", "stale"}} for each step with a result, and "ink_changed"."""
    out, ink = {}, None
    for rec in store.calibrations():  # newest first
        kind = _kind(rec)
        if kind == "ink_changed":
            ink = rec["time"] if ink is None else ink
            continue
        if kind not in STEPS or kind in out or rec.get("skipped"):
            continue
        result = rec.get("result") or {}
        if kind == "camera":
            result = {**result, "camera": rec["camera"]}
        out[kind] = {"date": rec["time"], "result": result, "method": rec.get("method", "guided")}
    for kind, entry in out.items():
        entry["stale"] = bool(kind in INK_SENSITIVE and ink is not None and entry["date"] < ink)
    return {**out, "ink_changed": ink}


def scan_extra(store, settings: dict) -> dict:
    """The scan.json keys for the calibration in force: "tank", "meniscus" (what processing
    uses) and "calibration" (what was used, with dates, for the report)."""
    force = in_force(store)
    used = {}
    extra = {}
    if "camera" in force:
        used["camera"] = {"date": force["camera"]["date"], "method": force["camera"]["method"]}
    if "tank" in force:
        area = float(force["tank"]["result"]["area_mm2"])
        extra["tank"] = {"inner_area_mm2": area}
        used["tank"] = {"date": force["tank"]["date"], "area_mm2": area, "method": force["tank"]["method"]}
    if "meniscus" in force:
        r = force["meniscus"]["result"]
        extra["meniscus"] = {
            "format": "inkslice.meniscus/1",
            "capillary_length_mm": r["capillary_length_mm"],
            "contact_angle_deg": r["contact_angle_deg"],
            "contact_line_curvature": r.get("contact_line_curvature", 0.0),
        }
        used["meniscus"] = {
            "date": force["meniscus"]["date"],
            "method": force["meniscus"]["method"],
            "reference": r.get("reference"),
        }
    at_home = float(settings["level_at_home_mm"])
    lz = force.get("level_zero")
    if lz is not None and abs(float(lz["result"]["level_at_home_mm"]) - at_home) < 1e-6:
        used["level_zero"] = {"date": lz["date"], "level_at_home_mm": at_home, "method": lz["method"]}
    else:
        used["level_zero"] = {"date": None, "level_at_home_mm": at_home, "method": "setting"}
    if force["ink_changed"]:
        used["ink_changed"] = force["ink_changed"]
    extra["calibration"] = used
    return extra


def stored_camera(store):
    """The camera block in force (commissioned or guided), or None."""
    force = in_force(store)
    return force["camera"]["result"]["camera"] if "camera" in force else None


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
        force = in_force(self.store)
        last = {}
        for rec in self.store.calibrations():
            k = _kind(rec)
            if k in STEPS and k not in last:
                last[k] = rec
        steps = []
        for k in STEPS:
            entry = force.get(k)
            if entry is not None:
                status = "stale" if entry["stale"] else "done"
            else:
                status = "skipped" if last.get(k, {}).get("skipped") else "missing"
            steps.append(
                {
                    "id": k,
                    "title": TITLES[k],
                    "status": status,
                    "result": _public(entry["result"]) if entry else None,
                    "method": entry["method"] if entry else None,
                    "date": entry["date"] if entry else None,
                    "date_text": _date(entry["date"] if entry else None),
                    "actions": list(IDLE_ACTIONS[k]) + ["skip"],
                }
            )
        s = self.session
        return {
            "steps": steps,
            "active": s.to_json(ACTIONS.get((s.step, s.stage), ())) if s else None,
            "ink_changed": force["ink_changed"],
            "ink_changed_text": _date(force["ink_changed"]),
            "board": {
                "inner_corners": [BOARD.cols, BOARD.rows],
                "square_mm": BOARD.square_mm,
                "jig_first_corner_mm": [JIG.x0, JIG.y0],
                "min_views": MIN_VIEWS,
                # what to print: the web serves these files from its static folder
                "printed_mm": list(printed_size_mm(BOARD)),
                "print": print_instructions(BOARD),
                "files": ["chessboard.pdf", "chessboard.png"],
            },
            "reference": {"kind": "ball", "default_diameter_mm": BALL_MM},
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
        force = in_force(self.store)
        return {
            "format": FORMAT,
            "exported": time.time(),
            "results": {
                k: {"date": force[k]["date"], "method": force[k]["method"], "result": force[k]["result"]}
                for k in STEPS
                if k in force
            },
            "ink_changed": force["ink_changed"],
        }

    def import_(self, doc) -> dict:
        results = _check_export(doc)
        if self.session is not None:
            raise SettingError(
                "commissioning",
                f"the {TITLES[self.session.step].lower()} step is in progress; "
                "finish or cancel it before importing",
            )
        if doc.get("ink_changed"):
            self.store.add_calibration({"kind": "ink_changed"}, when=doc["ink_changed"])
        for kind, entry in results.items():
            result = dict(entry["result"])
            record = {"kind": kind, "method": entry.get("method", "imported"), "imported": time.time()}
            if kind == "camera":
                record["camera"] = result.pop("camera")
            record["result"] = result
            self.store.add_calibration(record, when=entry["date"])
            if kind == "level_zero":
                self._set_level_zero(float(result["level_at_home_mm"]))
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

    def _preview(self, frame, corners=None, board: Board = BOARD):
        img = frame if frame.ndim == 3 else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        if corners is not None:
            img = img.copy()
            cv2.drawChessboardCorners(img, board.pattern, corners.astype(np.float32).reshape(-1, 1, 2), True)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 80])
        if ok:
            self.h.show_frame(buf.tobytes(), {"level_mm": None, "time": time.time(), "what": "commissioning"})

    def _store(self, kind, result, method, **more):
        self.store.add_calibration({"kind": kind, "result": result, "method": method, **more})
        self.store.event(None, "commissioning", f"{TITLES[kind]} stored ({method}): {_summary(kind, result)}")
        self.h.say(f"commissioning: {TITLES[kind]} stored: {_summary(kind, result)}")

    def _set_level_zero(self, value):
        current = self.h.settings()
        changes = {"level_at_home_mm": value}
        if current["levels_to_mm"] > value:
            changes["levels_to_mm"] = math.floor(value)  # the range cannot start above level zero
        self.h.update_settings(changes)

    # -- level zero -------------------------------------------------------------------
    def _level_zero_enter(self, values):
        value = _positive(values, "level_at_home_mm")
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
        """Raise the base in steps until its top shows above the ink, then halve the bracket."""
        s = self.session
        guess = float(self.h.settings()["level_at_home_mm"])
        stage = s.devices.stage

        def shows(pos):
            stage.move_to(pos)
            frame = self._frame(s)
            return _bright_fraction(frame) > BASE_SHOWS, frame

        lo = max(guess - LEVEL_SEARCH_MM, 0.0)
        if shows(lo)[0]:
            raise SettingError(
                "level zero",
                f"the base already shows at stage position {lo:.1f} mm; "
                "is the tank filled, and the base empty?",
            )
        pos, found = lo, None
        while pos < guess + LEVEL_SEARCH_MM:
            pos = round(pos + 1.0, 6)
            up, frame = shows(pos)
            if up:
                found = pos
                break
        if found is None:
            raise SettingError(
                "level zero",
                f"the base never showed between stage positions {lo:.1f} and "
                f"{pos:.1f} mm: is the light on and the base in view?",
            )
        below, above = found - 1.0, found
        while above - below > LEVEL_RESOLUTION_MM:
            mid = (above + below) / 2
            up, frame = shows(mid)
            if up:
                above = mid
            else:
                below = mid
        value = round((above + below) / 2, 4)
        self._preview(frame)
        s.pending = {"level_at_home_mm": value}
        s.detected = {
            "level_at_home_mm": value,
            "resolution_mm": LEVEL_RESOLUTION_MM,
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
            f"view ({len(s.views)} of at least {MIN_VIEWS} taken), then take the view; "
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
        lens = {}
        if len(s.views) >= MIN_VIEWS:
            intr = intrinsics(s.views, BOARD)
            lens = {"K": intr.K, "dist": intr.dist, "rms_px": intr.rms_px, "from": f"{len(s.views)} views"}
        elif s.views:
            raise SettingError(
                "views",
                f"{len(s.views)} board views taken: take at least {MIN_VIEWS} for "
                "the lens, or cancel and start again to keep the stored lens",
            )
        else:
            cam = stored_camera(self.store) or {}
            if cam.get("K") is not None:
                lens = {
                    "K": np.asarray(cam["K"], float),
                    "dist": np.asarray(cam["dist"], float),
                    "from": "the stored calibration",
                    "height_mm": cam.get("height_mm"),
                }
        self._place(
            "board_flat",
            "Lay the board flat on the base, centred, its rows along the base's "
            "x side; the stage raises it to the ink line",
            **_board_details(),
        )
        s.devices.stage.move_to(float(self.h.settings()["level_at_home_mm"]))
        frame = self._frame(s)
        K, dist = lens.get("K"), lens.get("dist")
        Hm, height, rms_mm = plane_homography(frame, BOARD, JIG, K, dist, "flat board")
        h, w = frame.shape[:2]
        camera = camera_json((w, h), Hm, K, dist, height if height is not None else lens.get("height_mm"))
        c = np.array([[w / 2, h / 2, 1], [w / 2 + 1, h / 2, 1]]) @ Hm.T
        c = c[:, :2] / c[:, 2:]
        report = {
            "views": len(s.views),
            "plane_rms_mm": round(rms_mm, 4),
            "mm_per_px": round(float(np.linalg.norm(c[1] - c[0])), 4),
            "lens": lens.get("from", "none (no lens model)"),
            "camera_height_mm": round(camera["height_mm"], 2) if camera.get("height_mm") else None,
        }
        if "rms_px" in lens:
            report["lens_rms_px"] = round(lens["rms_px"], 4)
        s.pending = {"camera": camera, "report": report}
        s.detected = report
        s.stage = "check"
        self._preview(frame, find_corners(frame, BOARD))

    def _camera_accept(self, values):
        pending = self.session.pending
        self._end("camera", "done")
        self.store.add_calibration(
            {"kind": "camera", "camera": pending["camera"], "result": pending["report"], "method": "measured"}
        )
        self.store.event(None, "commissioning", f"camera stored: {pending['report']}")
        self.h.say(f"commissioning: camera stored ({_summary('camera', pending['report'])})")

    # -- tank -------------------------------------------------------------------------
    def _tank_enter(self, values):
        if "area_mm2" in values:
            area = _positive(values, "area_mm2")
            result = {"area_mm2": round(area, 1), "figure": f"{area:.0f} mm²"}
        else:
            w, d = _positive(values, "width_mm"), _positive(values, "depth_mm")
            area = w * d
            result = {
                "area_mm2": round(area, 1),
                "width_mm": w,
                "depth_mm": d,
                "figure": f"{w:g} x {d:g} mm = {area:.0f} mm²",
            }
        if not 100.0 <= area <= 1e6:
            raise SettingError("tank", f"{area:.0f} mm² is not a tank's inner area (100 .. 1 000 000 mm²)")
        self._store("tank", result, "entered")

    # -- meniscus ---------------------------------------------------------------------
    def _meniscus_start(self, values):
        d = float(values.get("diameter_mm", BALL_MM))
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
        step = float(values.get("level_step_mm", 0.5))
        top = math.ceil((d + 1.0) / step) * step
        changes = {
            "levels_to_mm": top,
            "levels_from_mm": max(round(d / 2 - 2.0, 3), 0.0),
            "level_step_mm": step,
            "step_mode": "fixed",
        }
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
            s.detected = {"diameter_mm": s.detected["diameter_mm"], **_public(s.pending)}
            s.stage = "check"
        else:
            s.stage, s.error = "failed", f"the reference scan {job['status']}: {job['reason']}"

    def _meniscus_accept(self, values):
        result = dict(self.session.pending)
        self._end("meniscus", "done")
        self._store("meniscus", result, "measured")


def reference_processor(reference: dict):
    """The processor of a reference scan (the meniscus step): fit the meniscus, process the scan
    with it and measure the ball; writes reference.json, meniscus.json and heightmap.csv."""

    def run(scan_folder, out_folder, options, stop=None):
        from pathlib import Path

        from .. import atomicio
        from ..outputs import meniscus_json, write_heightmap_csv
        from ..process import extract_waterlines, process
        from ..scanfile import load_scan
        from ..surface.reference import Ball, fit_meniscus, reference_error

        def check_stop():  # it runs in the scan's thread: a cancel must not wait for it
            if stop is not None and stop.is_set():
                raise Cancelled()

        scan = load_scan(scan_folder)
        waterlines = extract_waterlines(scan)
        check_stop()
        model, ball = fit_meniscus(scan, Ball(float(reference["diameter_mm"])), waterlines)
        check_stop()
        job = process(
            scan_folder,
            truth=False,
            meniscus=model,
            **{k: v for k, v in options.items() if k in ("grid_n", "method")},
        )
        hm = job.heightmap
        err = reference_error(ball, hm)
        out = Path(out_folder)
        result = {
            "capillary_length_mm": round(model.capillary_length_mm, 4),
            "contact_angle_deg": round(math.degrees(model.contact_angle_rad), 3),
            "contact_line_curvature": round(model.curvature, 3),
            "reference": {**ball.to_json(), **err},
            "reference_job": scan.extra.get("job"),
            "tank_area_mm2": (scan.extra.get("tank") or {}).get("inner_area_mm2"),
        }
        atomicio.write_json(out / "reference.json", result)
        atomicio.write_json(out / "meniscus.json", meniscus_json(model))
        write_heightmap_csv(out / "heightmap.csv", hm)
        # a measurement, not a part to mill: the job is done without a finishing program
        return {"outputs": ["heightmap.csv", "meniscus.json", "reference.json"], "makes_program": False}

    return run


# -- small helpers --------------------------------------------------------------------------


def _bright_fraction(frame) -> float:
    """Share of the frame brighter than the ink (the lit base top or part)."""
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    small = cv2.resize(
        gray, (256, max(1, round(gray.shape[0] * 256 / gray.shape[1]))), interpolation=cv2.INTER_AREA
    )
    return float(np.mean(small > 90))


def _positive(values, key) -> float:
    v = values.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise SettingError(key, f"must be a positive number of mm, got {v!r}")
    return float(v)


def _public(result: dict) -> dict:
    """A result as the page shows it: without the camera's matrices."""
    return {k: v for k, v in result.items() if k != "camera"}


def _summary(kind, r) -> str:
    if kind == "level_zero":
        return f"base top meets the ink at stage position {r['level_at_home_mm']:.3f} mm"
    if kind == "tank":
        return r["figure"]
    if kind == "meniscus":
        ref = r.get("reference") or {}
        text = f"capillary length {r['capillary_length_mm']:.3f} mm, contact angle {r['contact_angle_deg']:.1f} deg"
        if "mean_abs_error_mm" in ref:
            text += (
                f"; this box measures the {ref['diameter_mm']:g} mm ball to {ref['mean_abs_error_mm']:.3f} mm"
            )
        return text
    if kind == "camera":
        return f"{r.get('mm_per_px')} mm/px, plane RMS {r.get('plane_rms_mm')} mm, lens: {r.get('lens')}"
    return ""


def _check_export(doc) -> dict:
    where = "commissioning file"
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SettingError(where, f"not a commissioning export (format {FORMAT!r} expected)")
    results = doc.get("results")
    if not isinstance(results, dict):
        raise SettingError(where, "'results' must be an object of step: result")
    for kind, entry in results.items():
        if kind not in STEPS:
            raise SettingError(where, f"unknown step {kind!r}")
        if (
            not isinstance(entry, dict)
            or not isinstance(entry.get("result"), dict)
            or not isinstance(entry.get("date"), (int, float))
        ):
            raise SettingError(where, f"{kind}: needs a date and a result")
        r = entry["result"]
        need = {
            "level_zero": ("level_at_home_mm",),
            "tank": ("area_mm2",),
            "camera": ("camera",),
            "meniscus": ("capillary_length_mm", "contact_angle_deg"),
        }[kind]
        for key in need:
            if key not in r:
                raise SettingError(where, f"{kind}: {key} is missing")
        if kind == "camera":
            try:
                read_camera(where, r["camera"])
            except InkSliceError as e:
                raise SettingError(where, f"camera: {e.problem}") from None
    ink = doc.get("ink_changed")
    if ink is not None and not isinstance(ink, (int, float)):
        raise SettingError(where, "ink_changed must be a date (seconds) or null")
    return results
