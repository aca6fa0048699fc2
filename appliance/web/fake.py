"""A stand-in for the daemon's BenchService, for tests, benches and UI work.

It follows the facade agreed with the daemon team (state, start_scan, cancel,
resume, jobs, job, job_file, latest_frame, settings, update_settings,
subscribe, close) and simulates a scan in a thread: homing, N levels at a
fixed period with a rendered camera frame per level (a dome seen from above,
its waterline drawn in red), then processing, which writes real files into the
job folder: heightmap.csv, toolpath.gcode (+ one file per G-code dialect),
surface.stl, report.md, report.json and error.png.

It also has the optional extras the web UI shows when a service offers them:
live_heightmap() (the map growing as levels complete), calibration steps and
import_scan() for an uploaded scan folder.

It is not a model of the daemon's internals: it exists so that the web room
can be built and tested against the facade while the daemon is being built.
"""

from __future__ import annotations

import copy
import json
import math
import queue
import secrets
import threading
import time
from pathlib import Path

import cv2
import numpy as np

from ..atomicio import write_bytes, write_json, write_text
from ..daemon import settings as S
from ..errors import DeviceError, InkSliceError, SettingError

# The daemon's own settings schema: the fake refuses and accepts exactly what the daemon does.
DEFAULT_SETTINGS = dict(S.DEFAULTS)
DIALECT_FILES = {
    "linuxcnc": "toolpath-linuxcnc.ngc",
    "grbl": "toolpath-grbl.nc",
    "fanuc": "toolpath-fanuc.nc",
}
TANK_MM = 60.0  # the simulated camera sees a 60 x 60 mm patch
DOME_H = 20.0  # dome height, mm
DOME_R = 25.0  # dome footprint radius, mm


def dome(x, y):
    r2 = (x - TANK_MM / 2) ** 2 + (y - TANK_MM / 2) ** 2
    return np.where(r2 < DOME_R**2, DOME_H * (1 - r2 / DOME_R**2), np.nan)


def validate_settings(current: dict, changes: dict) -> dict:
    return S.validate(current, changes)


class FakeBenchService:
    """Thread-safe; one scan at a time. `level_s` is the simulated time per level."""

    def __init__(
        self, data_dir, level_s=0.15, home_s=0.3, process_s=0.3, frame_px=320, settings=None, usb=None
    ):
        """`usb`: what finds sticks and copies to them (hw.usb.UsbExporter, or a test's own), or None."""
        self.data_dir = Path(data_dir)
        self.usb = usb
        self.jobs_dir = self.data_dir / "jobs"
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        self.level_s, self.home_s, self.process_s, self.frame_px = level_s, home_s, process_s, frame_px
        self._lock = threading.RLock()
        self._settings = validate_settings(DEFAULT_SETTINGS, settings or {})
        self._jobs: dict[str, dict] = {}
        self._state = self._blank_state()
        self._frame = None
        self._thread = None
        self._stop = threading.Event()
        self._subscribers: list[queue.Queue] = []
        self._calibration = {"step": 0, "detected": None}
        self._live = None
        self.scan_durations: list[float] = []  # seconds per finished scan, for the load bench

    # -- facade ---------------------------------------------------------------
    def state(self) -> dict:
        with self._lock:
            return copy.deepcopy(self._state)

    def start_scan(self, params: dict) -> str:
        params = dict(params or {})
        with self._lock:
            if self._state["state"] in ("homing", "scanning", "processing"):
                raise SettingError("scan", f"a scan is already running ({self._state['job_id']})")
            settings = validate_settings(
                self._settings, {k: v for k, v in params.items() if k in DEFAULT_SETTINGS}
            )
            unknown = [k for k in params if k not in DEFAULT_SETTINGS and k not in ("name",)]
            if unknown:
                raise SettingError(unknown[0], "unknown scan parameter")
            job_id = time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(2)
            levels = self._levels(settings)
            job = {
                "id": job_id,
                "name": str(params.get("name", ""))[:80],
                "status": "homing",
                "reason": "",
                "created": time.time(),
                "started": time.time(),
                "finished": None,
                "settings": settings,
                "outputs": [],
                "levels_total": len(levels),
                "levels_done": 0,
            }
            self._jobs[job_id] = job
            self._begin(job, levels, 0)
            return job_id

    def cancel(self):
        with self._lock:
            if self._thread is None or self._state["state"] not in ("homing", "scanning", "processing"):
                return
            self._stop.set()
        self._thread.join(timeout=5)

    def resume(self, job_id: str) -> str:
        with self._lock:
            job = self._get(job_id)
            if job["status"] not in ("cancelled", "failed"):
                raise SettingError(
                    "job", f"job {job_id} is {job['status']}; only a cancelled or failed scan resumes"
                )
            if self._state["state"] in ("homing", "scanning", "processing"):
                raise SettingError("scan", "a scan is already running")
            levels = self._levels(job["settings"])
            self._begin(job, levels, job["levels_done"])
            return job_id

    def jobs(self) -> list[dict]:
        with self._lock:
            return [
                self._public(j) for j in sorted(self._jobs.values(), key=lambda j: j["created"], reverse=True)
            ]

    def job(self, job_id: str) -> dict:
        with self._lock:
            return self._public(self._get(job_id))

    def repost(self, job_id: str, options: dict | None = None) -> list:
        """As the daemon does (daemon/repost.py): a new program from the job's height map."""
        from ..daemon import settings as S
        from ..daemon.repost import repost

        with self._lock:
            job = self._get(job_id)
            if job["status"] != "done":
                raise InkSliceError("job", f"job {job_id} is {job['status']}; wait for it to finish")
            settings = S.full(job["settings"])
        names = repost(self.jobs_dir / job["id"], job["id"], settings, options or {})
        with self._lock:
            job["outputs"] = sorted(set(job["outputs"]) | set(names))
        return names

    def job_file(self, job_id: str, name: str) -> Path:
        with self._lock:
            job = self._get(job_id)
        folder = (self.jobs_dir / job["id"]).resolve()
        path = (folder / name).resolve()
        if path.parent != folder or not path.is_file():
            raise InkSliceError(f"job {job_id}", f"no output named {name!r}")
        return path

    def latest_frame(self):
        with self._lock:
            return self._frame

    def usb_sticks(self) -> list[dict]:
        return [s.to_json() for s in self.usb.sticks()] if self.usb is not None else []

    def export_to_usb(self, job_id: str, name: str = "toolpath.gcode", stick=None, release=True) -> dict:
        if self.usb is None:
            raise DeviceError("usb", "USB export is switched off on this box")
        return self.usb.export(
            self.job_file(job_id, name), stick, f"{job_id}-{name}", release=release
        ).to_json()

    def settings(self) -> dict:
        with self._lock:
            return dict(self._settings)

    def update_settings(self, changes: dict) -> dict:
        with self._lock:
            self._settings = validate_settings(self._settings, changes)
            return dict(self._settings)

    def subscribe(self, timeout: float = 30.0):
        """Yields state dicts as they change, for at most `timeout` seconds."""
        q: queue.Queue = queue.Queue(maxsize=100)
        with self._lock:
            self._subscribers.append(q)
        end = time.monotonic() + timeout
        try:
            yield self.state()
            while True:
                left = end - time.monotonic()
                if left <= 0:
                    return
                try:
                    yield q.get(timeout=left)
                except queue.Empty:
                    return
        finally:
            with self._lock:
                self._subscribers.remove(q)

    def close(self):
        self.cancel()

    # -- optional extras the UI uses when present -------------------------------
    def live_heightmap(self):
        """The height map so far: {x: [...], y: [...], z: [[...]] with None off-part or not yet seen}."""
        with self._lock:
            return copy.deepcopy(self._live)

    CALIBRATION_STEPS = (
        ("home", "Empty the tank's base and home the stage"),
        ("target", "Put the calibration plate (printed dot grid) on the base, lower it to the ink"),
        ("detect", "Capture a frame and find the dots"),
        ("accept", "Check the preview and accept the camera model"),
    )

    def calibration(self) -> dict:
        with self._lock:
            return {
                "steps": [{"id": s, "text": t} for s, t in self.CALIBRATION_STEPS],
                "step": self._calibration["step"],
                "detected": self._calibration["detected"],
                "holds_bench": self._calibration["step"] > 0,
            }

    def calibrate(self, step: str) -> dict:
        ids = [s for s, _ in self.CALIBRATION_STEPS]
        if step == "cancel":  # as the daemon: any step, back to "home", nothing stored
            with self._lock:
                self._calibration = {"step": 0, "detected": None}
            return self.calibration()
        if step not in ids:
            raise SettingError("step", f"unknown calibration step {step!r}")
        with self._lock:
            want = ids[self._calibration["step"] % len(ids)]
            if step != want:
                raise SettingError("step", f"do step {want!r} first")
            if step == "detect":
                img, dots = self._calibration_frame()
                self._frame = (img, {"level_mm": None, "time": time.time(), "what": "calibration"})
                self._calibration["detected"] = {
                    "dots": dots,
                    "mm_per_px": round(TANK_MM / self.frame_px, 4),
                    "rms_px": 0.21,
                }
            self._calibration["step"] = (self._calibration["step"] + 1) % len(ids)
            if step == "accept":
                self._calibration["detected"] = None
            return self.calibration()

    def import_scan(self, folder: Path) -> str:
        """An uploaded scan folder (already validated) becomes a job that is processed."""
        meta = json.loads((Path(folder) / "scan.json").read_text())
        with self._lock:
            if self._state["state"] in ("homing", "scanning", "processing"):
                raise SettingError("scan", "a scan is running; import it afterwards")
            job_id = time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(2)
            job = {
                "id": job_id,
                "name": "uploaded scan",
                "status": "done",
                "reason": "",
                "created": time.time(),
                "started": time.time(),
                "finished": None,
                "settings": dict(self._settings),
                "outputs": [],
                "levels_total": len(meta["frames"]),
                "levels_done": len(meta["frames"]),
            }
            self._jobs[job_id] = job
        import shutil

        shutil.copytree(folder, self.jobs_dir / job_id / "scan")  # the service keeps its own copy
        job["outputs"] = self._write_outputs(job)
        job["finished"] = time.time()
        return job_id

    # -- internals --------------------------------------------------------------
    @staticmethod
    def _levels(settings):
        a, b, s = settings["levels_from_mm"], settings["levels_to_mm"], settings["level_step_mm"]
        n = int(math.floor((b - a) / s + 1e-9)) + 1
        if n > 5000:
            raise SettingError("level_step_mm", f"{n} levels is more than the bench can take (5000)")
        # from the top down, as the daemon scans: the part emerges from the ink
        return [round(b - i * s, 6) for i in range(n)]

    def _get(self, job_id):
        job = self._jobs.get(job_id)
        if job is None:
            raise InkSliceError(f"job {job_id}", "no such job")
        return job

    @staticmethod
    def _public(job):
        out = {k: copy.deepcopy(v) for k, v in job.items()}
        return out

    def _blank_state(self):
        return {
            "state": "idle",
            "job_id": None,
            "level_mm": None,
            "levels_done": 0,
            "levels_total": 0,
            "eta_s": None,
            "message": "ready",
            "hardware": {"stage": "ok", "camera": "ok", "light": "ok", "display": "missing"},
        }

    def _set(self, **kw):
        with self._lock:
            self._state.update(kw)
            snap = copy.deepcopy(self._state)
            subs = list(self._subscribers)
        for q in subs:
            try:
                q.put_nowait(snap)
            except queue.Full:
                pass

    def _begin(self, job, levels, first):
        self._stop.clear()
        # The state says "homing" before start_scan returns, so a second start is refused at once.
        self._state = self._blank_state()
        self._state.update(
            state="homing",
            job_id=job["id"],
            levels_total=len(levels),
            levels_done=first,
            message="homing the stage",
        )
        job["status"] = "homing"
        if first == 0:
            n = 40
            self._live = {
                "x": [round(TANK_MM * (i + 0.5) / n, 3) for i in range(n)],
                "y": [round(TANK_MM * (i + 0.5) / n, 3) for i in range(n)],
                "z": [[None] * n for _ in range(n)],
            }
        self._thread = threading.Thread(
            target=self._run, args=(job, levels, first), daemon=True, name=f"fake-scan-{job['id']}"
        )
        self._thread.start()

    def _run(self, job, levels, first):
        t0 = time.monotonic()
        try:
            job["status"] = "homing"
            self._set(
                state="homing",
                job_id=job["id"],
                levels_total=len(levels),
                levels_done=first,
                message="homing the stage",
            )
            if self._stop.wait(self.home_s):
                return self._end(job, "cancelled", "cancelled by the operator")
            job["status"] = "scanning"
            for i in range(first, len(levels)):
                level = levels[i]
                self._set(
                    state="scanning",
                    level_mm=level,
                    message=f"level {level:.2f} mm",
                    eta_s=round((len(levels) - i) * self.level_s + self.process_s, 1),
                )
                if self._stop.wait(self.level_s):
                    return self._end(job, "cancelled", "cancelled by the operator")
                img = self._render(level)
                with self._lock:
                    self._frame = (img, {"level_mm": level, "time": time.time()})
                    self._grow(level)
                job["levels_done"] = i + 1
                self._set(levels_done=i + 1)
            job["status"] = "processing"
            self._set(
                state="processing", message="building the height map and the toolpath", eta_s=self.process_s
            )
            if self._stop.wait(self.process_s):
                return self._end(job, "cancelled", "cancelled by the operator")
            job["outputs"] = self._write_outputs(job)
            self._end(job, "done", "")
            self.scan_durations.append(time.monotonic() - t0)
        except Exception as e:  # a crash in the simulation shows as a failed job, like the daemon's
            self._end(job, "failed", f"{type(e).__name__}: {e}")

    def _end(self, job, status, reason):
        job["status"], job["reason"], job["finished"] = status, reason, time.time()
        self._set(state=status, message=reason or "scan finished", eta_s=0 if status == "done" else None)

    def _grow(self, level):
        n = len(self._live["x"])
        xs = np.array(self._live["x"])
        X, Y = np.meshgrid(xs, xs)
        Z = dome(X, Y)
        seen = Z >= level
        for r in range(n):
            for c in range(n):
                if seen[r, c] and self._live["z"][r][c] is None:
                    self._live["z"][r][c] = round(float(level), 3)

    def _render(self, level):
        n = self.frame_px
        img = np.zeros((n, n, 3), np.uint8)
        img[:] = (70, 25, 10)  # dark-blue ink (BGR)
        r_mm = DOME_R * math.sqrt(max(0.0, 1 - level / DOME_H))
        c = n // 2
        r = int(round(r_mm / TANK_MM * n))
        if r > 0:
            cv2.circle(img, (c, c), r, (215, 220, 225), -1, cv2.LINE_AA)
            cv2.circle(img, (c, c), r, (0, 0, 255), 2, cv2.LINE_AA)  # detected waterline
        cv2.putText(img, f"{level:.2f} mm", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 80])
        return buf.tobytes()

    def _calibration_frame(self):
        n = self.frame_px
        img = np.full((n, n, 3), 235, np.uint8)
        dots = []
        for i in range(1, 8):
            for j in range(1, 8):
                p = (i * n // 8, j * n // 8)
                cv2.circle(img, p, 4, (20, 20, 20), -1)
                cv2.circle(img, p, 7, (0, 160, 0), 1)
                dots.append(p)
        ok, buf = cv2.imencode(".jpg", img)
        return buf.tobytes(), len(dots)

    def _write_outputs(self, job):
        folder = self.jobs_dir / job["id"]
        folder.mkdir(parents=True, exist_ok=True)
        n = 24
        xs = TANK_MM * (np.arange(n) + 0.5) / n
        X, Y = np.meshgrid(xs, xs)
        Z = dome(X, Y)
        lines = ["x,y,z"]
        for r in range(n):
            for c in range(n):
                if np.isfinite(Z[r, c]):
                    lines.append(f"{X[r, c]:.4f},{Y[r, c]:.4f},{Z[r, c]:.4f}")
        write_text(folder / "heightmap.csv", "\n".join(lines) + "\n")
        files = ["heightmap.csv"]
        for dialect, name in DIALECT_FILES.items():
            text = self._gcode(X, Y, Z, dialect)
            write_text(folder / name, text)
            files.append(name)
            if dialect == job["settings"]["dialect"]:
                write_text(folder / "toolpath.gcode", text)
                files.append("toolpath.gcode")
        if "toolpath.gcode" not in files:  # a dialect the fake does not draw: linuxcnc's program
            write_text(folder / "toolpath.gcode", self._gcode(X, Y, Z, "linuxcnc"))
            files.append("toolpath.gcode")
        write_bytes(folder / "surface.stl", self._stl(X, Y, np.nan_to_num(Z)).encode())
        files.append("surface.stl")
        err = np.abs(np.sin(X / 5) * np.cos(Y / 7)) * 0.05
        err[~np.isfinite(Z)] = np.nan
        vis = np.nan_to_num(err / 0.05 * 255).astype(np.uint8)
        png = cv2.applyColorMap(
            cv2.resize(vis, (240, 240), interpolation=cv2.INTER_NEAREST), cv2.COLORMAP_VIRIDIS
        )
        ok, buf = cv2.imencode(".png", png)
        write_bytes(folder / "error.png", buf.tobytes())
        files.append("error.png")
        stats = {
            "rms_mm": round(float(np.sqrt(np.nanmean(err**2))), 4),
            "max_mm": round(float(np.nanmax(err)), 4),
            "levels": job["levels_total"],
            "cells": int(np.isfinite(Z).sum()),
        }
        write_json(
            folder / "report.json", {"job": job["id"], "statistics": stats, "settings": job["settings"]}
        )
        md = [f"# Scan {job['id']}", "", "| statistic | value |", "|---|---|"]
        md += [f"| {k} | {v} |" for k, v in stats.items()]
        md += ["", "Error picture: `error.png`"]
        write_text(folder / "report.md", "\n".join(md) + "\n")
        files += ["report.json", "report.md"]
        return sorted(files)

    @staticmethod
    def _gcode(X, Y, Z, dialect):
        head = {
            "linuxcnc": ["G21 G90 G17", "F800"],
            "grbl": ["G21 G90", "F800"],
            "fanuc": ["%", "O1000", "G21 G90 G17", "F800"],
        }[dialect]
        out = list(head) + ["G0 Z25.000"]
        safe = 25.0
        for r in range(X.shape[0]):
            cols = range(X.shape[1]) if r % 2 == 0 else range(X.shape[1] - 1, -1, -1)
            for c in cols:
                z = Z[r, c] if np.isfinite(Z[r, c]) else 0.0
                out.append(f"G1 X{X[r, c]:.3f} Y{Y[r, c]:.3f} Z{z:.3f}")
        out += [f"G0 Z{safe:.3f}", "M2" if dialect != "fanuc" else "M30"]
        if dialect == "fanuc":
            out.append("%")
        return "\n".join(out) + "\n"

    @staticmethod
    def _stl(X, Y, Z):
        out = ["solid surface"]
        for r in range(X.shape[0] - 1):
            for c in range(X.shape[1] - 1):
                p = [
                    (X[r, c], Y[r, c], Z[r, c]),
                    (X[r, c + 1], Y[r, c + 1], Z[r, c + 1]),
                    (X[r + 1, c], Y[r + 1, c], Z[r + 1, c]),
                    (X[r + 1, c + 1], Y[r + 1, c + 1], Z[r + 1, c + 1]),
                ]
                for tri in ((p[0], p[1], p[2]), (p[1], p[3], p[2])):
                    out.append("facet normal 0 0 1\nouter loop")
                    out += [f"vertex {a:.4f} {b:.4f} {z:.4f}" for a, b, z in tri]
                    out.append("endloop\nendfacet")
        out.append("endsolid surface")
        return "\n".join(out) + "\n"
