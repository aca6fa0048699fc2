"""Device fakes for the daemon, in the style of OctoPrint's virtual printer:
they behave like the real devices and their faults are switched on by config.

    stage = FakeStage(faults={"reset_after_moves": 5})
    camera = FakeCamera(surface, rig, level_mm=lambda: 60 - stage.position_mm,
                        faults={"unplug_after": 3})

FakeStage: an in-memory lifting stage with the firmware's observable rules
(moves refused until homed, a reset forgets the home, an emergency stop
needs a re-home). Faults:
  unplug_after_moves N  every command after the N-th move raises DeviceError
  reset_after_moves N   the MCU "resets" after the N-th move: homed=False,
                        flags.fresh_boot=True, the next move is refused
  seconds_per_mm S      real time a move takes (so a scan lasts long enough
                        to be killed at random points)

FakeCamera: renders a top view of a known surface at the level the callable
returns at capture time. The frame is a pure function of the level (noise is
seeded from the level, never from a counter) so a resumed scan captures
exactly the frames an uninterrupted one would. It ignores the perspective of
the part above the liquid (the renderer team's VirtualCamera models it).
Faults: unplug_after N (captures after the N-th raise DeviceError).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from ..errors import DeviceError, SettingError
from ..hw.base import BenchFactory, Camera, Display, OutputLine, Stage, StageStatus


class FakeStage(Stage):
    def __init__(self, steps_per_mm: float = 1600.0, travel_mm: float = 80.0, faults: dict | None = None):
        self.steps_per_mm = float(steps_per_mm)
        self.travel_steps = round(travel_mm * steps_per_mm)
        self.faults = dict(faults or {})
        self.position_steps = round(self.travel_steps / 2)  # somewhere; unknown until homed
        self.homed = False
        self.fresh_boot = True
        self.estopped = False
        self.moves = 0
        self.calls: list[str] = []  # what was asked, for tests ("home", "move 12.5", "stop")
        self._lock = threading.Lock()

    @property
    def position_mm(self) -> float:
        return self.position_steps / self.steps_per_mm

    def _check_plugged(self):
        n = self.faults.get("unplug_after_moves")
        if n is not None and self.moves >= n:
            raise DeviceError("stage fake", "no reply from the controller (unplugged?)")

    def identify(self) -> dict:
        self._check_plugged()
        return {"name": "inkslice-stepper", "fw": "fake", "proto": 1}

    def home(self, timeout: float = 60.0) -> None:
        with self._lock:
            self.calls.append("home")
            self._check_plugged()
            self.estopped = False
            self._travel(self.position_steps, 0)
            self.homed, self.fresh_boot, self.estopped = True, False, False

    def move_to(self, position_mm: float, timeout: float = 60.0) -> None:
        with self._lock:
            self.calls.append(f"move {position_mm:.4f}")
            self._check_plugged()
            target = round(position_mm * self.steps_per_mm)
            if not self.homed:
                raise DeviceError("stage fake", "MOVE refused: not homed (the controller was reset?)")
            if not 0 <= target <= self.travel_steps:
                raise SettingError("stage move", f"{position_mm:.3f} mm is outside the travel")
            self._travel(self.position_steps, target)
            self.moves += 1
            n = self.faults.get("reset_after_moves")
            if n is not None and self.moves == n:
                self.homed, self.fresh_boot = False, True

    def _travel(self, start, target):
        """Go from start to target in real time (seconds_per_mm); an emergency stop
        halts it where it is, like the firmware."""
        s = self.faults.get("seconds_per_mm", 0.0)
        duration = s * abs(target - start) / self.steps_per_mm
        t0 = time.monotonic()
        while s and time.monotonic() - t0 < duration:
            if self.estopped:
                frac = (time.monotonic() - t0) / duration
                self.position_steps = round(start + frac * (target - start))
                raise DeviceError("stage fake", "move stopped: emergency stop")
            time.sleep(min(0.01, duration))
        self.position_steps = target

    def status(self) -> StageStatus:
        self._check_plugged()
        state = "estop" if self.estopped else "idle"
        return StageStatus(
            state, self.position_steps, self.position_mm, self.homed, {"fresh_boot": self.fresh_boot}
        )

    def travel_mm(self) -> tuple[float, float]:
        return 0.0, self.travel_steps / self.steps_per_mm

    def stop(self) -> None:
        self.calls.append("stop")
        self._check_plugged()
        self.estopped, self.homed = True, False


def small_rig(width=640, height=480):
    """The virtual bench's rig scaled to a small frame (same field of view)."""
    from .rig import Rig

    base = Rig()
    k = width / base.width
    return Rig(
        width=width,
        height=height,
        focal_px=base.focal_px * k,
        principal_u=base.principal_u * k,
        principal_v=base.principal_v * height / base.height,
    )


class FakeCamera(Camera):
    def __init__(self, surface, rig, level_mm, faults: dict | None = None):
        from .rig import pixel_map

        self.surface, self.rig, self.level_mm = surface, rig, level_mm
        self.faults = dict(faults or {})
        self.captures = 0
        self._map = pixel_map(rig, True)
        self.closed = False

    def capture(self) -> np.ndarray:
        n = self.faults.get("unplug_after")
        if self.closed or (n is not None and self.captures >= n):
            raise DeviceError("camera fake", "no frame: the camera is gone (unplugged?)")
        self.captures += 1
        return self.render(float(self.level_mm()))

    def render(self, level: float) -> np.ndarray:
        m = self._map
        sdf = self.surface.level_sdf(m.x0, m.y0, level)
        cover = np.clip(0.5 + sdf / m.pix, 0.0, 1.0).astype(np.float32)[..., None]
        ink = np.array(self.rig.ink_bgr, np.float32)
        part = np.array(self.rig.part_bgr, np.float32)
        img = ink + cover * (part - ink)
        rng = np.random.default_rng(round(level * 10000) & 0xFFFFFFFF)  # seeded by the level
        img += rng.normal(0.0, 2.0, img.shape[:2])[..., None].astype(np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def close(self) -> None:
        self.closed = True


def replay_name(level_mm: float) -> str:
    return f"{round(level_mm * 1000):07d}.png"


class ReplayCamera(Camera):
    """Frames rendered beforehand, one PNG per level (replay_name), served at the
    level the callable returns: the daemon then holds one decoded frame at a
    time, as with the real V4L2 camera, and a memory figure of the daemon is not
    inflated by a renderer running inside it."""

    def __init__(self, folder, level_mm):
        self.folder, self.level_mm = Path(folder), level_mm

    def capture(self) -> np.ndarray:
        import cv2

        path = self.folder / replay_name(float(self.level_mm()))
        frame = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if frame is None:
            raise DeviceError("camera replay", f"no frame {path.name} for level {self.level_mm():.3f} mm")
        return frame


class FakeLine(OutputLine):
    """An output line that remembers its history (light, LED, MCU reset)."""

    def __init__(self, name="line"):
        self.name, self.on, self.history = name, False, []

    def set(self, on: bool) -> None:
        self.on = bool(on)
        self.history.append(self.on)


class FakeButton:
    """A push button; tests press it with .press() (short) or .long_press() (held ~2 s).

    poll() answers like GpioButton's: "short", "long" or None, once per press.
    """

    def __init__(self):
        self._presses: list[str] = []

    def press(self):
        self._presses.append("short")

    def long_press(self):
        self._presses.append("long")

    def poll(self) -> str | None:
        return self._presses.pop(0) if self._presses else None


class FakeDisplay(Display):
    def __init__(self):
        self.lines: list[str] = []

    def show(self, lines: list[str]) -> None:
        self.lines = list(lines)


class FakeLevelSensor:
    """A liquid-level sensor reading a callable (mm above the base top)."""

    def __init__(self, level_mm):
        self.level_mm = level_mm

    def read_mm(self) -> float:
        return float(self.level_mm())


# -- device factories for BenchService (see appliance/daemon/service.py) --------


class _KnownPart:
    """What the simulated benches add to a device factory: they know the part in the tank.

    `processor(inner)` wraps one of daemon/processing.py's processors: while a
    scan's devices are open (the job being captured, then processed), the
    part is written beside the scan folder as its ground truth and the report
    gets statistics against it. An imported scan, processed with no devices
    open, gets none.
    """

    part_in_view = None  # the surface name while a scan's devices are open

    def _showing(self, devices, part):
        self.part_in_view = part
        devices.closers.append(lambda: setattr(self, "part_in_view", None))
        return devices

    def processor(self, inner):
        from ..daemon.processing import EarlyChild, child_process
        from .truth import find_truth, truth_path, write_truth

        CHILD = "appliance.sim.processing_child"

        def with_truth(scan_folder, options):
            if self.part_in_view is not None:
                write_truth(scan_folder, self.part_in_view)
            # the job folder is replaced by the outputs: the truth file stays beside the scan
            return {**options, "keep": [*options.get("keep", ()), truth_path(scan_folder).name]}

        def process(scan_folder, out_folder, options, stop=None):
            options = with_truth(scan_folder, options)
            if inner is child_process:
                return child_process(scan_folder, out_folder, options, stop, module=CHILD)
            from ..process import process_scan

            return process_scan(scan_folder, out_folder, truth=find_truth(scan_folder), **options)

        if inner is child_process:
            # the child that follows the capture (daemon/processing.py), with the truth too
            process.follow = lambda scan_folder, out_folder, options: EarlyChild(  # type: ignore[attr-defined]
                scan_folder, out_folder, with_truth(scan_folder, options), module=CHILD
            )
        return process


class FakeBench(_KnownPart, BenchFactory):
    """The whole bench in memory: FakeStage + FakeCamera over a known surface,
    fake light, LED, button and display. `faults` switches faults on:

        {"stage": {...FakeStage faults}, "camera": {...FakeCamera faults},
         "panel": {"display": "missing"},
         "disk": {"after_frames": 3, "free_mb": 150}}   # the disk "fills up" after 3 frames

    `last` is the Devices of the latest open(), for tests to inspect.
    `replay`: a folder of frames rendered beforehand (ReplayCamera) instead
    of rendering in this process.
    """

    extra_params = ("surface",)

    def __init__(
        self,
        surface: str = "sphere",
        rig=None,
        faults: dict | None = None,
        replay=None,
        level_sensor: bool = False,
        level_at_home_mm: float | None = None,
    ):
        self.surface, self.replay, self.level_sensor = surface, replay, level_sensor
        # the bench's true liquid level above the base top with the stage at home; None: the
        # daemon's setting is right (commissioning's level zero measures it)
        self.level_at_home_mm = level_at_home_mm
        self.placement = None  # what the operator was asked to put on the base (staging.py)
        self.rig = rig or small_rig(320, 240)
        self.faults = dict(faults or {})
        self.last = None
        self.panel = None
        self._disk_checks = 0

    def disk_free_mb(self, path) -> float:
        """Free space as the daemon sees it (BenchService's disk_free_mb hook)."""
        import shutil

        disk = self.faults.get("disk")
        self._disk_checks += 1
        if disk and self._disk_checks > disk.get("after_frames", 0):
            return float(disk["free_mb"])
        return shutil.disk_usage(path).free / 1e6

    def check(self, params):
        from .surfaces import get

        return {
            **params,
            "surface": get(params.get("surface") or self.surface).name,
        }  # SettingError if unknown

    def open(self, settings, params):
        from ..hw.devices import Devices
        from .effects import Effects
        from .staging import StagedCamera
        from .surfaces import get

        stage = FakeStage(faults=self.faults.get("stage"))
        at_home = float(
            self.level_at_home_mm if self.level_at_home_mm is not None else settings["level_at_home_mm"]
        )
        level = lambda: at_home - stage.position_mm
        if self.replay:
            camera = ReplayCamera(self.replay, level)
        else:
            camera = FakeCamera(
                get(params.get("surface") or self.surface), self.rig, level, faults=self.faults.get("camera")
            )
            camera = StagedCamera(
                self, camera, lambda part: FakeCamera(part, self.rig, level), level, self.rig, Effects()
            )
        light = FakeLine("light")
        sensor = None
        if self.level_sensor:
            # reads the ink's true level: the nominal one lowered by the emerged volume
            from .physics import true_level

            part, area = get(params.get("surface") or self.surface), self.rig.tank_area_mm2
            sensor = FakeLevelSensor(lambda: true_level(part, level(), area))
        self.last = Devices(
            stage,
            camera,
            self.rig.camera_model(),
            light=light,
            level_sensor=sensor,
            hardware={"stage": "ok", "camera": "ok", "light": "ok"},
        )
        return self._showing(self.last, get(params.get("surface") or self.surface).name)

    def open_panel(self):
        from ..hw.devices import Devices
        from .staging import SimOperator

        missing = self.faults.get("panel", {})
        hw, parts = {}, {}
        for name, make in (
            ("led", lambda: FakeLine("led")),
            ("button", FakeButton),
            ("display", FakeDisplay),
        ):
            if name in missing:
                hw[name], parts[name] = "missing", None
            else:
                hw[name], parts[name] = "ok", make()
        self.panel = Devices(None, None, hardware=hw, operator=SimOperator(self), **parts)
        return self.panel


def LevelSeededCamera(surface, rig, level_mm, effects=None, clock=None):
    """The renderer's VirtualCamera, its noise seeded from the level instead of a
    frame counter: a resumed scan then sees exactly the frames an uninterrupted
    one saw (VirtualCamera counts frames from 0 in each process). With a clock
    and effects with ripple_mm > 0 the ink rings after each move (the daemon
    tells it when a move finished) and the settle time has something to wait out."""
    from .camera import VirtualCamera
    from .render import render_frame

    class _Camera(VirtualCamera):
        def capture(self):
            level = float(self.level_mm())
            effects = self._effects_now(level)
            rng = np.random.default_rng([self.seed, round(level * 10000) & 0xFFFFFFFF])
            self.frames_taken += 1
            self.last_level_mm = level
            return render_frame(self.surface, level, self.rig, effects, rng)

    return _Camera(surface, rig, level_mm, effects=effects, clock=clock)


class _SettledStage(Stage):
    """The simulated stage as the rippling virtual ink needs it: when a move or
    a homing ends, the camera's ripple clock restarts (the ink rings from the
    moment the base stops, and the daemon's settle time waits it out)."""

    def __init__(self, stage, camera):
        self.stage, self.camera = stage, camera

    def __getattr__(self, name):  # counters, info, ...: the real driver's
        return getattr(self.stage, name)

    def identify(self):
        return self.stage.identify()

    def home(self, timeout=60.0):
        self.stage.home(timeout)
        self.camera.note_move_finished()

    def move_to(self, position_mm, timeout=60.0):
        self.stage.move_to(position_mm, timeout)
        self.camera.note_move_finished()

    def status(self):
        return self.stage.status()

    def stop(self):
        self.stage.stop()

    def travel_mm(self):
        return self.stage.travel_mm()

    def close(self):
        self.stage.close()


class SimulatedBenchFactory(_KnownPart, BenchFactory):
    """The simulated bench: the real firmware under simavr (appliance/sim/hil.py)
    driven by the real SerialStage, and the renderer's VirtualCamera looking at
    where the simulated stage really is. Falls back to FakeCamera when the
    renderer's module is not there. One SimulatedBench lives as long as the
    factory; each job opens a fresh SerialStage on its pty."""

    extra_params = ("surface",)

    def __init__(
        self,
        surface: str = "sphere",
        rig=None,
        speed: float | None = None,
        effects=None,
        clock=None,
        level_at_home_mm: float | None = None,
    ):
        from .hil import SimulatedBench

        self.surface, self.rig, self.effects, self.clock = surface, rig or small_rig(320, 240), effects, clock
        self.level_at_home_mm = level_at_home_mm  # the bench's truth (see FakeBench); None: the setting's
        self.placement = None
        self.bench = SimulatedBench() if speed is None else SimulatedBench(speed=speed)
        self.last = None

    def check(self, params):
        return FakeBench.check(self, params)

    def _camera(self, surface, level_mm):
        return LevelSeededCamera(surface, self.rig, level_mm, effects=self.effects, clock=self.clock)

    def open(self, settings, params):
        from ..hw.devices import Devices
        from ..hw.stage import SerialStage
        from .staging import StagedCamera
        from .surfaces import get

        stage = SerialStage(self.bench.port, auto_rehome=False)
        at_home = float(
            self.level_at_home_mm if self.level_at_home_mm is not None else settings["level_at_home_mm"]
        )
        level = lambda: at_home - self.bench.stage_position_mm()
        part = self._camera(get(params.get("surface") or self.surface), level)
        model = self.rig.camera_model(distorted=part.effects.lens_distortion)
        camera = StagedCamera(
            self, part, lambda other: self._camera(other, level), level, self.rig, part.effects
        )
        light = FakeLine("light")
        if self.clock is not None:
            stage = _SettledStage(stage, part)
        self.last = Devices(
            stage,
            camera,
            model,
            light=light,
            hardware={"stage": "ok", "camera": "ok", "light": "ok"},
            closers=[camera.close, stage.close],
        )
        return self._showing(self.last, part.surface.name)

    def open_panel(self):
        return FakeBench.open_panel(self)

    faults: dict = {}

    def close(self):
        self.bench.close()
