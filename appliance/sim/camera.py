"""The virtual camera: renders what the bench's camera would see right now.

The daemon drives it exactly like the real V4L2 camera (appliance.hw.base.Camera).
The level comes from a callable evaluated at capture time - the daemon team
feeds it the level derived from the simulated firmware's real stage position -
so a frame taken before a move finished shows the old level, as on a real bench.

Ripple (optional): after the level changes the free surface oscillates with a
decaying amplitude (physics.ripple_offset). With a `clock` (seconds, e.g.
time.monotonic or a simulated clock) the camera notes when the level last
changed and renders the ripple of that age, so the daemon's settle step has
something real to wait for.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..hw.base import Camera
from . import surfaces as _surfaces
from .effects import Effects, effects_preset
from .render import render_frame
from .rig import Rig


class VirtualCamera(Camera):
    def __init__(
        self,
        surface,
        rig: Rig = None,
        level_mm: Callable[[], float] = None,
        effects=None,
        seed: int = 0,
        clock: Callable[[], float] = None,
    ):
        if isinstance(surface, str):
            surface = _surfaces.get(surface)
        if isinstance(effects, str):
            effects = effects_preset(effects)
        if level_mm is None:
            raise TypeError("VirtualCamera needs level_mm: a callable returning the ink level (mm)")
        self.surface = surface
        self.rig = rig or Rig()
        self.level_mm = level_mm
        self.effects = effects or Effects()
        self.seed = seed
        self.clock = clock
        self.frames_taken = 0
        self._last_level = None
        self._moved_at = None
        self.last_level_mm = None  # the level the last frame was rendered at (for tests/logs)
        self.last_ripple_age_s = None

    def _effects_now(self, level: float) -> Effects:
        if self.clock is None or self.effects.ripple_mm <= 0:
            return self.effects
        now = self.clock()
        if self._last_level is None or abs(level - self._last_level) > 1e-9:
            # the level changed since we last looked: the surface starts ringing now
            self._moved_at = now if self._last_level is not None else now - 1e3
        self._last_level = level
        age = now - self._moved_at
        self.last_ripple_age_s = age
        return replace(self.effects, ripple_age_s=age)

    def camera_model(self):
        """The TRUE scan.json camera for the frames this camera takes: with the
        lens distortion only if its effects put it in the frames."""
        return self.rig.camera_model(distorted=self.effects.lens_distortion)

    def note_move_finished(self):
        """Optional hint: the stage just stopped (restarts the ripple clock)."""
        if self.clock is not None:
            self._moved_at = self.clock()
            self._last_level = float(self.level_mm())

    def capture(self) -> np.ndarray:
        level = float(self.level_mm())
        effects = self._effects_now(level)
        rng = np.random.default_rng([self.seed, self.frames_taken])
        self.frames_taken += 1
        self.last_level_mm = level
        return render_frame(self.surface, level, self.rig, effects, rng)
