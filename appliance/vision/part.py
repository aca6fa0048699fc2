"""Where the part stands out of the ink in one frame, as a small mask.

The daemon asks this while it scans: does the first frame show the part (then
the scan must start higher), how much of the waterline moved between two
frames (the adaptive step), what the live height map and the preview's
outline show. The answer is the waterline extractor's (pipeline.py) on that
frame alone: the same channel choice, threshold, colour test against glare
and speck filter that processing will apply, so the daemon never scans for
a part that processing would not see, nor misses one it would.
"""

from __future__ import annotations

import cv2
import numpy as np

from .pipeline import WaterlineExtractor

WIDTH = 256  # px across the mask: cheap to compare, ~0.6 mm a pixel on a 160 mm field


def find_part(frame: np.ndarray, camera, level_mm: float, width: int = WIDTH) -> np.ndarray:
    """A boolean picture `width` px across, true where the part stands above the ink.

    `camera` is the scan's CameraModel (the frame size it expects); `level_mm`
    names the frame in errors (FrameError: wrong size, truncated...)."""
    extractor = WaterlineExtractor(camera, no_part="empty")
    extractor.extract(frame, level_mm)
    h, w = frame.shape[:2]
    k = width / w
    mask = np.zeros((max(1, round(h * k)), width), np.uint8)
    for pixels, hole in extractor.outline:  # outer loops come before their holes
        contour = np.rint((pixels + 0.5) * k - 0.5).astype(np.int32).reshape(-1, 1, 2)
        cv2.drawContours(mask, [contour], -1, 0 if hole else 1, cv2.FILLED)
    return mask.astype(bool)
