"""Which level to capture next: a fixed step, or an adaptive one that goes
finer where the waterline changes fast between frames.

The plan is a pure function of the frames already in the scan (their target
levels and the `change` measured when each was taken, both kept in
scan.json), so a resumed scan asks for exactly the levels an uninterrupted
one would have.

Levels run from the top (part under the ink) down to the bottom (the base
top: the part fully exposed); the stage rises to lower the liquid relative
to the part.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

EPS = 1e-6
PART_THRESHOLD = 70          # grey level between the dark ink and the (even shaded) lit part
WORK_WIDTH = 256             # the change measure runs on a frame this wide: cheap at 2048 px too


def part_mask(frame: np.ndarray) -> np.ndarray:
    """A small boolean picture of what stands above the ink."""
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    h, w = gray.shape
    small = cv2.resize(gray, (WORK_WIDTH, max(1, round(h * WORK_WIDTH / w))), interpolation=cv2.INTER_AREA)
    return small > PART_THRESHOLD


def waterline_change(before: np.ndarray | None, after: np.ndarray) -> float:
    """Fraction of the part's area that changed side of the waterline between two masks."""
    if before is None:
        return 0.0
    changed = np.count_nonzero(before ^ after)
    area = max(np.count_nonzero(before), np.count_nonzero(after))
    return changed / area if area else 0.0


class LevelPlan:
    def __init__(self, settings: dict):
        self.top = float(settings["levels_to_mm"])
        self.bottom = float(settings["levels_from_mm"])
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
        """(target level, step that led to it) after `frames`, or None when the scan is complete."""
        if not frames:
            return self.top, 0.0
        last = frames[-1].extra
        last_target = float(last.get("target_mm", frames[-1].level_mm))
        if last_target <= self.bottom + EPS:
            return None
        if self.mode == "fixed":
            k = len(frames)                         # computed, not accumulated: no drift
            target = self.top - k * self.step
            step = self.step
        else:
            step = self.next_step(float(last.get("step_mm") or self.step), float(last.get("change", 0.0)))
            target = last_target - step
        if target < self.bottom + EPS:
            target = self.bottom                    # the last frame: the part fully exposed
        return round(target, 6), round(step, 6)

    def estimate_total(self, frames: list) -> int:
        """Levels in the whole scan (exact for a fixed step, an estimate for adaptive)."""
        if self.mode == "fixed":
            n = (self.top - self.bottom) / self.step
            return int(math.floor(n + EPS)) + 1 + (1 if n - math.floor(n + EPS) > EPS else 0)
        nxt = self.next_target(frames)
        if nxt is None:
            return len(frames)
        step = nxt[1] or self.step
        return len(frames) + 1 + int(math.ceil((nxt[0] - self.bottom) / max(step, self.step_min) - EPS))
