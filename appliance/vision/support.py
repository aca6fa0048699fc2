"""Monotone exposure: what the next lower frames confirm of a frame's part.

Seen from above, a ray that meets the part above the liquid at level L still
meets it at every lower level: a pixel that shows part at L shows part in every
lower frame. Glare that drifts and flickers, a bubble, a speck float on the ink
and move on. So the waterline extractor (pipeline.py) may be given the next
lower frames (`below`, nearest first; processing reads two ahead): a pixel
counts as part only if it is part-like in each of them too (the same threshold
and colour test, without the glare cut, grown by a pixel for the stage's play).
Only 8-bit masks of those frames are kept, one per frame.

One thing fixed to the part does recede as the ink drops: an edge standing above the ink.
The part rises towards the camera, so the edge is seen further from the camera's foot at
every lower level, by |x - C| dL / H (1.3 px at 30 mm from the foot, 1 mm steps, 300 mm
up). Where that edge has ink on the foot's side of it - the far shore of a pool a pocket
held when the ink went down (the tank's ink stands at the foot of its walls instead) - the
lower frames show ink where this one shows part, and the edge would be cut away as if it
were glare. Asked to (the extractor's raised_shores, for a scan whose pocket may have held
ink: waterlines.py), each lower frame also confirms as it would look with such edges put back
where they stood in this frame: scaled towards the camera's foot by 1 - dL / H (`Raised`).
Glare that vanishes is still cut: it is nowhere near part in the lower frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .frames import Hue, channel_view

GROW = np.ones((3, 3), np.uint8)


@dataclass(frozen=True)
class Raised:
    """Where the camera is, in the frame: its foot (the pixel over which it stands, u, v)
    and its height above the ink (mm); how an edge standing above the ink moves."""

    foot_px: tuple
    height_mm: float

    def put_back(self, mask, dl):
        """`mask` of a frame dl mm lower as raised edges would show in this frame."""
        f = 1.0 - dl / self.height_mm
        u, v = self.foot_px
        M = np.float32([[f, 0, (1 - f) * u], [0, f, (1 - f) * v]])
        h, w = mask.shape
        return cv2.warpAffine(mask, M, (w, h), flags=cv2.INTER_NEAREST)


def support_mask(frame, roi, shape, channel: int, threshold: int, hue: Hue | None) -> np.ndarray:
    """Where a lower frame may show part: at or above `threshold` and not the ink's blue
    (the glare cut is left out: a face may be brighter there), grown by one pixel.
    Full frame (`shape`), 0/255; zero outside `roi`."""
    x0, y0, x1, y1 = roi
    mask = np.zeros(shape, np.uint8)
    main = np.ascontiguousarray(channel_view(frame[y0:y1, x0:x1], channel))
    part = cv2.threshold(cv2.medianBlur(main, 3), threshold - 1, 255, cv2.THRESH_BINARY)[1]
    if hue is not None:
        other = np.ascontiguousarray(channel_view(frame[y0:y1, x0:x1], hue.other))
        blue = cv2.subtract(other, main)
        cv2.threshold(blue, hue.cut, 255, cv2.THRESH_BINARY_INV, blue)
        cv2.bitwise_and(part, blue, part)
    cv2.dilate(part, GROW, mask[y0:y1, x0:x1])
    return mask


class LowerFrames:
    """The next lower frames of the frame being read, their masks, and where they cut it."""

    def __init__(self, roi, shape, raised: Raised | None = None):
        self.roi, self.shape = roi, shape
        self.raised = raised  # None: no camera geometry known, lower frames as they are
        self.level = 0.0  # of the frame being read
        self.frames: list = []  # (level_mm, frame), nearest first
        self.masks: dict = {}  # level -> support_mask of that frame, made once
        self.cut: tuple | None = None  # (box, mask): where this frame's part was cut back by them

    def use(self, below, level) -> None:
        """The lower frames of the next frame (at `level`); masks of frames no longer among
        them go."""
        self.frames = [(float(lv), f) for lv, f in below]
        self.level = float(level)
        self.cut = None
        levels = {lv for lv, _ in self.frames}
        for lv in list(self.masks):
            if lv not in levels:
                del self.masks[lv]

    def mask(self, level, frame, channel: int, threshold: int, hue: Hue | None) -> np.ndarray:
        """support_mask of one lower frame, with the threshold known when it is first asked."""
        m = self.masks.get(level)
        if m is None:
            m = self.masks[level] = support_mask(frame, self.roi, self.shape, channel, threshold, hue)
        return m

    def confirm(self, binary, box, channel: int, threshold: int, hue: Hue | None) -> None:
        """Keep as part, inside `box` of the full-frame 0/255 `binary` (changed in place),
        only pixels the lower frames show part-like too."""
        self.cut = None
        if not self.frames:
            return
        x0, y0, x1, y1 = box
        inside = binary[y0:y1, x0:x1]
        before = inside.copy()
        for level, frame in self.frames:
            m = self.mask(level, frame, channel, threshold, hue)
            if self.raised is not None and self.level > level:
                m = cv2.bitwise_or(m, self.raised.put_back(m, self.level - level))
            cv2.bitwise_and(inside, m[y0:y1, x0:x1], inside)
        cut = cv2.subtract(before, inside)
        if cv2.countNonZero(cut):
            # the contour along a cut follows the lower frames' part, not an edge of this
            # one: its pixels (and their neighbours) give no waterline points
            self.cut = (box, cv2.dilate(cut, GROW))

    def uncut(self, pixels) -> np.ndarray:
        """True for contour pixels that are not on a cut made by confirm()."""
        if self.cut is None:
            return np.ones(len(pixels), bool)
        (x0, y0, x1, y1), cut = self.cut
        u, v = pixels[:, 0] - x0, pixels[:, 1] - y0
        inside = (u >= 0) & (u < x1 - x0) & (v >= 0) & (v < y1 - y0)
        keep = np.ones(len(pixels), bool)
        keep[inside] = cut[v[inside], u[inside]] == 0
        return keep
