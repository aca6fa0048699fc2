"""One scan, start to finish (or to a clear reason why not).

    home -> for each level: move, check the stage, settle, light on, capture,
    light off, find the part (vision/part.py), write the frame -> processing -> done

The levels come from levels.py's plan: it starts higher when the first frame
shows the part, and ends when the base is fully exposed. When a flat face came
out of the ink all at once between two levels (vision/refine.py), the runner
goes back up into that step and bisects it before it carries on down; those
frames are ordinary level frames, marked with the step they refine.

The frame PNG is written atomically first, then scan.json (atomically) with
the new frame listed, then the job row: scan.json never lists a frame that is
not fully on disk, and recovery only has to catch the row up with it.

Every way out of `run` leaves the hardware safe: light off, and on any
failure or cancel the motor stopped (an emergency stop; the next scan or the
resume re-homes anyway). A resumed job re-homes, then continues from the
frames in its scan.json, with the settings it started with.
"""

from __future__ import annotations

import errno
import logging
import shutil
import threading
import time
from collections.abc import Callable

import numpy as np

from ..errors import Cancelled, DeviceError, InkSliceError
from ..hw.devices import Devices
from ..scanfile import FrameRef, Scan, load_scan, read_frame, write_frame, write_scan_json
from ..vision.camera import CameraModel
from ..vision.camera_block import read_camera
from ..vision.part import find_part
from ..vision.refine import mask_pixel_mm, next_refinement, surfaced_faces
from . import processing
from . import settings as S
from .commissioned import scan_extra, stored_camera
from .levels import LevelPlan, waterline_change

log = logging.getLogger("inkslice.runner")


def _target_of(frame) -> float:
    return float(frame.extra.get("target_mm", frame.level_mm))


def _descent(frames) -> list:
    """The frames of the plan (levels.py), without those that refined a step."""
    return [f for f in frames if "refines" not in f.extra]


def free_mb(path) -> float:
    return shutil.disk_usage(path).free / 1e6


class ScanRunner:
    """Runs one job in the calling thread; `report(**state)` publishes progress."""

    def __init__(
        self,
        store,
        job_id: str,
        devices: Devices,
        processor: Callable,
        report: Callable,
        stop: threading.Event,
        on_frame: Callable | None = None,
        disk_free_mb: Callable = free_mb,
    ):
        self.store, self.job_id, self.dev = store, job_id, devices
        self.processor, self.report, self.stop = processor, report, stop
        self.on_frame = on_frame or (lambda image, info: None)
        self.disk_free_mb = disk_free_mb
        job = store.get_job(job_id)
        self.settings = job["settings"]
        self.params = job["params"]
        self.job_dir = store.job_dir(job_id)
        self.scan_dir = self.job_dir / "scan"
        self.plan: LevelPlan | None = None  # made in run(), once the stage's travel is known
        self._mask = None  # the part in the last frame of the descent
        self._scan: Scan | None = None
        self._level_times: list[float] = []
        self._early: processing.EarlyChild | None = None  # the processing child following the capture

    # -- the whole job ----------------------------------------------------------
    def run(self) -> str:
        """Returns the final status: done, failed or cancelled (also stored with the reason)."""
        try:
            scan = self._scan = self._open_scan()
            self.plan = LevelPlan(self.settings, self._ceiling())
            pending = self._pending_refinement(scan)
            if pending or self.plan.next_target(scan.frames) is not None:
                self._early = processing.start_early(
                    self.processor, self.scan_dir, self.job_dir, S.full(self.settings)
                )
                self._home()
                if pending:
                    self._refine(scan, *pending)
                self._capture_all(scan)
            self._light(False)
            outputs = self._process()
            self._finish("done", "", outputs=outputs)
            return "done"
        except Cancelled:
            self._make_safe()
            return self._cancelled()
        except InkSliceError as e:
            self._make_safe()
            if self.stop.is_set():  # the stop we asked for interrupted a move
                return self._cancelled()
            self._finish("failed", str(e))
            return "failed"
        except OSError as e:
            self._make_safe()
            if e.errno in (errno.ENOSPC, errno.EDQUOT):
                self._finish("failed", f"disk: full while writing ({e.strerror}); the frames so far are kept")
            else:
                self._finish("failed", f"file system: {e}")
            return "failed"
        except Exception as e:  # a bug must still end the job cleanly
            log.exception("scan %s crashed", self.job_id)
            self._make_safe()
            self._finish("failed", f"internal error: {type(e).__name__}: {e}")
            return "failed"
        finally:
            if self._early is not None:  # done with, or the scan ended before its capture did
                self._early.close()

    def _cancelled(self) -> str:
        reason = getattr(self.stop, "reason", "cancelled by the operator")
        self._finish("cancelled", f"{reason}; the frames so far are kept, resume to continue")
        return "cancelled"

    def _finish(self, status, reason, outputs=None):
        fields = dict(status=status, reason=reason, finished=time.time(), interrupted=0)
        if outputs is not None:
            fields["outputs"] = outputs
        if self._scan is not None:  # the row may lag scan.json if a write failed
            fields["levels_done"] = len(self._scan.frames)
        try:
            self.store.update_job(self.job_id, **fields)
            self.store.event(self.job_id, status, reason or "scan finished")
        except Exception:
            # e.g. the disk is so full SQLite cannot commit: the store holds the end in memory
            # and writes it when there is room (store.py). Say so, carry on.
            log.exception("could not record the end of job %s (%s: %s)", self.job_id, status, reason)
        self.report(state=status, message=reason or "scan finished", eta_s=0 if status == "done" else None)

    def _make_safe(self):
        """Light off, motor stopped. Each step on its own: one failing must not skip the other."""
        self._light(False)
        try:
            self.dev.stage.stop()
        except Exception as e:
            log.warning("could not stop the stage (%s): it may be unplugged or unpowered", e)

    def _light(self, on):
        if self.dev.light is not None:
            try:
                self.dev.light.set(on)
            except Exception as e:
                if on:
                    raise DeviceError("light", f"cannot switch it on: {e}") from None
                log.warning("could not switch the light off: %s", e)

    def _check_stop(self):
        if self.stop.is_set():
            raise Cancelled()

    # -- the scan folder --------------------------------------------------------
    def _open_scan(self) -> Scan:
        if (self.scan_dir / "scan.json").is_file():
            scan = load_scan(self.scan_dir)  # a resume: continue from its frames
            if scan.frames:
                last = _descent(scan.frames)[-1]
                self._mask = self._part_in(scan, last)
            return scan
        camera = self._calibrated_camera()
        self.scan_dir.mkdir(parents=True, exist_ok=True)
        extra = {
            "job": self.job_id,
            "name": self.params.get("name", ""),
            "level_at_home_mm": self.settings["level_at_home_mm"],
        }
        extra.update(scan_extra(self.store, self.settings))  # tank, meniscus, what was used and when
        # scan.json is written with the first frame: load_scan rejects an empty frame list
        return Scan(self.scan_dir, camera, [], extra)

    def _calibrated_camera(self) -> CameraModel:
        """The commissioned camera; without one, the model the devices bring (if any)."""
        stored = stored_camera(self.store)
        if stored is not None:
            return read_camera("calibration", stored)
        if self.dev.camera_model is not None:
            return self.dev.camera_model
        raise DeviceError("camera", "no camera calibration stored: commission the camera before scanning")

    def _part_in(self, scan: Scan, ref: FrameRef) -> np.ndarray:
        return find_part(read_frame(scan, ref), scan.camera, ref.level_mm)

    def _pending_refinement(self, scan: Scan):
        """A resumed scan first finishes the refinement of its last step, if the cut came
        during one: (upper, lower, faces, seen) read back from the frames, or None. The same
        masks give the same decisions, so it takes the frames an uninterrupted scan would."""
        descent = _descent(scan.frames)
        if float(S.full(self.settings)["refine_mm"]) <= 0 or len(descent) < 2:
            return None
        upper, lower = _target_of(descent[-2]), _target_of(descent[-1])
        if upper <= lower:
            return None
        below = self._mask if self._mask is not None else self._part_in(scan, descent[-1])
        faces = surfaced_faces(
            self._part_in(scan, descent[-2]), below, mask_pixel_mm(scan.camera, below.shape)
        )
        if not faces:
            return None
        seen = [
            (_target_of(f), self._part_in(scan, f))
            for f in scan.frames
            if f.extra.get("refines") == [upper, lower]
        ]
        return upper, lower, faces, seen

    # -- motion and capture -----------------------------------------------------
    def _home(self):
        self._check_stop()
        self.report(state="homing", message="homing the stage")
        self.store.update_job(self.job_id, status="homing")
        self._light(False)
        self.dev.stage.home()

    def _capture_all(self, scan: Scan):
        self.store.update_job(self.job_id, status="scanning")
        while True:
            self._check_stop()
            nxt = self.plan.next_target(scan.frames)
            if nxt is None:
                return
            t0 = time.monotonic()
            target, step = nxt
            total = self.plan.estimate_total(scan.frames)
            self.report(
                state="scanning",
                level_mm=target,
                levels_done=len(scan.frames),
                levels_total=total,
                message=f"level {target:.3f} mm",
                eta_s=self._eta(len(scan.frames), total),
            )
            level = self._move_to_level(target)
            if self.stop.wait(self.settings["settle_s"]):
                raise Cancelled()
            frame = self._capture()
            mask = find_part(frame, scan.camera, level)
            previous = _descent(scan.frames)[-1:]
            rising = bool(previous) and target > _target_of(previous[0])
            before = None if rising or not previous else self._mask
            change = waterline_change(before, mask)
            self._mask = mask
            extra = {
                "target_mm": target,
                "step_mm": step,
                "change": round(change, 6),
                "shows_part": bool(mask.any()),
            }
            self._keep(scan, frame, level, mask, extra, t0)
            if before is not None:
                self._refine(
                    scan,
                    _target_of(previous[0]),
                    target,
                    surfaced_faces(before, mask, mask_pixel_mm(scan.camera, mask.shape)),
                    [],
                )

    def _keep(self, scan: Scan, frame, level, mask, extra, t0):
        """Save one frame with its extra keys, publish it and the progress."""
        extra.update(self._sensor_reading(level))
        self._save_frame(scan, frame, FrameRef(f"frames/{len(scan.frames) + 1:04d}.png", level, extra))
        self.on_frame(frame, {"level_mm": level, "time": time.time(), "part": mask})
        self._level_times.append(time.monotonic() - t0)
        total = self.plan.estimate_total(scan.frames)
        self.store.update_job(self.job_id, levels_done=len(scan.frames), levels_total=total, level_mm=level)
        self.report(
            levels_done=len(scan.frames), levels_total=total, eta_s=self._eta(len(scan.frames), total)
        )

    def _refine(self, scan: Scan, upper: float, lower: float, faces, seen):
        """Faces came out at once between the levels `upper` and `lower`: go back into that
        step and bisect it (vision/refine.py) until each face's level is known to refine_mm.
        Raising the ink over a face it has just left needs twice the settle time (it must
        close over the face and calm down); `seen` holds [(level, mask)] already taken."""
        resolution = float(S.full(self.settings)["refine_mm"])
        if resolution <= 0 or not faces:
            return
        here = lower
        while True:
            self._check_stop()
            target = next_refinement(upper, lower, faces, seen, resolution)
            if target is None:
                return
            t0 = time.monotonic()
            self.report(
                state="scanning",
                level_mm=target,
                message=f"level {target:.3f} mm (a face came out "
                f"at once between {upper:g} and {lower:g} mm: refining)",
            )
            level = self._move_to_level(target)
            if self.stop.wait(self.settings["settle_s"] * (2 if target > here else 1)):
                raise Cancelled()
            here = target
            frame = self._capture()
            mask = find_part(frame, scan.camera, level)
            seen.append((target, mask))
            self._keep(
                scan,
                frame,
                level,
                mask,
                {"target_mm": target, "refines": [upper, lower], "shows_part": bool(mask.any())},
                t0,
            )

    def _ceiling(self) -> float:
        """The highest level the stage reaches: the ink's level with the stage at the home end of its travel."""
        return float(self.settings["level_at_home_mm"]) - self.dev.stage.travel_mm()[0]

    def _move_to_level(self, target: float) -> float:
        """Move so the ink stands at `target`; return the nominal level the stage really reached."""
        at_home = float(self.settings["level_at_home_mm"])
        self.dev.stage.move_to(at_home - target)
        st = self.dev.stage.status()
        if not st.homed or st.flags.get("fresh_boot"):
            raise DeviceError(
                "stage",
                "the controller was reset during the scan (position lost); "
                "the frames so far are kept, resume to re-home and continue",
            )
        if st.state in ("alarm", "estop"):
            raise DeviceError("stage", f"the controller is in {st.state} ({st.flags.get('alarm', '')})")
        return round(at_home - st.position_mm, 6)

    def _capture(self) -> np.ndarray:
        self._light(True)
        try:
            frame = self.dev.camera.capture()
        finally:
            self._light(False)
        if frame is None or frame.ndim not in (2, 3):
            raise DeviceError("camera", "returned no image")
        return frame

    def _sensor_reading(self, nominal: float) -> dict:
        """The liquid-level sensor's reading, kept with the frame to cross-check the
        displacement model (the ink drops as the part emerges). Never fails a scan."""
        if self.dev.level_sensor is None:
            return {}
        try:
            measured = float(self.dev.level_sensor.read_mm())
        except Exception as e:
            log.warning("level sensor: %s", e)
            return {}
        return {
            "sensor_level_mm": round(measured, 3),
            "sensor_minus_nominal_mm": round(measured - nominal, 3),
        }

    def _save_frame(self, scan: Scan, frame: np.ndarray, ref: FrameRef):
        need = float(self.settings["min_free_mb"])
        free = self.disk_free_mb(self.scan_dir)
        if free < need:
            raise DeviceError(
                "disk",
                f"nearly full: {free:.0f} MB free, scans stop below {need:.0f} MB; "
                f"the {len(scan.frames)} frames so far are kept",
            )
        write_frame(self.scan_dir, ref.file, frame)
        scan.frames.append(ref)
        try:
            write_scan_json(scan)
        except BaseException:
            scan.frames.pop()  # scan.json on disk still lists the old frames
            raise

    def _eta(self, done, total):
        if not self._level_times:
            return None
        per = sum(self._level_times[-10:]) / len(self._level_times[-10:])
        return round(per * max(total - done, 0), 1)

    # -- processing -------------------------------------------------------------
    def _process(self) -> list[str]:
        self._check_stop()
        processing.release_freed_memory()  # before the state says so: the capture's heap is gone
        self.store.update_job(self.job_id, status="processing")
        self.report(state="processing", message="building the height map and the toolpath", eta_s=None)
        return processing.run(
            self.processor, self.store, self.job_id, S.full(self.settings), self.stop, self._early
        )
