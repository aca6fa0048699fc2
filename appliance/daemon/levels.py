"""Which level to capture next: a fixed step, or an adaptive one that goes
finer where the waterline changes fast between frames.

Levels run from the top (part under the ink) down to the bottom (the base
top: the part fully exposed); the stage rises to lower the liquid relative
to the part. The scan ends with a frame at the bottom level.

The top takes care of itself: when the highest frame so far shows the part,
the part is taller than the range and the next level is twice as high above
the bottom, up to the ceiling (the highest level the stage reaches).
The descent then starts from the first level that shows no part and skips
the levels already captured on the way up. A part still standing out at the
ceiling stops the scan: PartTooTall.

Frames that refine a step (marked `refines`: the runner went back into a step
in which a face came out at once, vision/refine.py) are not the plan's: it
carries on below them as if they were not there.

The plan is a pure function of the frames already in the scan (their target
levels, whether each showed the part, and the `change` measured when each
was taken, all kept in scan.json), so a resumed scan asks for exactly the
levels an uninterrupted one would have.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InkSliceError

EPS = 1e-6


class PartTooTall(InkSliceError):
    """The part stands out of the ink at the highest level the stage reaches."""

    def __init__(self, level_mm: float):
        super().__init__(
            "scan range",
            f"the part is taller than the range: it still stands out of the ink at "
            f"{level_mm:g} mm, the highest level the stage reaches (lower the "
            f"part on its base, or fill more ink and calibrate level zero again)",
        )


def waterline_change(before: np.ndarray | None, after: np.ndarray) -> float:
    """Fraction of the part's area that changed side of the waterline between two masks."""
    if before is None:
        return 0.0
    changed = np.count_nonzero(before ^ after)
    area = max(np.count_nonzero(before), np.count_nonzero(after))
    return changed / area if area else 0.0


class LevelPlan:
    def __init__(self, settings: dict, ceiling_mm: float | None = None):
        self.top = float(settings["levels_to_mm"])
        self.bottom = float(settings["levels_from_mm"])
        self.ceiling = self.top if ceiling_mm is None else max(self.top, float(ceiling_mm))
        self.mode = settings["step_mode"]
        self.step = float(settings["level_step_mm"])
        self.step_min = float(settings["step_min_mm"])
        self.step_max = float(settings["step_max_mm"])
        self.target_change = float(settings["adaptive_change"])

    def next_step(self, last_step: float, change: float) -> float:
        """The adaptive rule: aim at `adaptive_change`; grow at most 2x per frame."""
        if self.mode == "fixed":
            return self.step
        if change <= 0:
            return min(self.step_max, 2 * last_step)
        proposal = last_step * self.target_change / change
        return float(min(self.step_max, 2 * last_step, max(self.step_min, proposal)))

    def next_target(self, frames: list) -> tuple[float, float] | None:
        """(target level, step that led to it) after `frames`, or None when the scan is complete.

        Raises PartTooTall when the part stands out of the ink at the ceiling."""
        frames = [f for f in frames if "refines" not in f.extra]  # a refined step's extra frames
        if not frames:
            return self.top, 0.0
        targets = [_target(f) for f in frames]
        if min(targets) <= self.bottom + EPS:
            return None  # the base is fully exposed: done
        high = max(range(len(frames)), key=lambda i: (targets[i], -i))
        if frames[high].extra.get("shows_part"):
            if targets[high] >= self.ceiling - EPS:
                raise PartTooTall(targets[high])
            # twice as high above the bottom: a few frames reach any height the stage allows
            return round(min(self.ceiling, 2 * targets[high] - self.bottom), 6), 0.0
        # the descent: from the lowest frame taken after the highest one, over levels already taken
        last = min(range(high, len(frames)), key=lambda i: targets[i])
        level, info = targets[last], frames[last].extra
        step = self.next_step(float(info.get("step_mm") or self.step), float(info.get("change", 0.0)))
        while True:
            target = round(level - step, 6)
            if target < self.bottom + EPS:
                return self.bottom, round(step, 6)  # the last frame: the part fully exposed
            passed = [t for t in targets if target - EPS <= t < level - EPS]
            if not passed:
                return target, round(step, 6)
            level = min(passed)  # captured on the way up: carry on below it

    def estimate_total(self, frames: list) -> int:
        """Levels in the whole scan (exact for a fixed step with the range as set, else an estimate)."""
        try:
            nxt = self.next_target(frames)
        except PartTooTall:
            return len(frames)
        if nxt is None:
            return len(frames)
        target, step = nxt
        if not frames or step == 0.0:  # the first frame, or a level above the range
            step = self.step
            target = max(target, self.top)
        if self.mode == "fixed":
            n = (target - self.bottom) / step
            return len(frames) + int(math.floor(n + EPS)) + 1 + (1 if n - math.floor(n + EPS) > EPS else 0)
        return len(frames) + 1 + int(math.ceil((target - self.bottom) / max(step, self.step_min) - EPS))


def _target(frame) -> float:
    return float(frame.extra.get("target_mm", frame.level_mm))
