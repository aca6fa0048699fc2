"""The frames just above the first one that showed the part, read again.

A top comes out of the ink as a sliver or a speck, too thin or faint for a frame on
its own to tell from noise (the scan's first frames also teach the threshold and the
colour test). Read with what the frame below taught - its channel, threshold, colour
test - over the tiles of its part, and confirmed by the frames below, the sliver is
found; then the frame above that, over the sliver's tiles, until one shows nothing.
The extractor is copied for this and left as it was.
"""

from __future__ import annotations

import copy

import cv2
import numpy as np

from .frames import NoPartError, check_image
from .types import Waterline


def read_above(extractor, above, below=()) -> list[Waterline]:
    """The waterlines of the frames `above` that show the part's top, nearest first.

    `extractor` (a pipeline.WaterlineExtractor: not imported, pipeline imports this) has
    just read the first frame showing the part. above: (level_mm, frame)
    pairs going up, nearest first; below: the frames below the one above them all,
    (level_mm, frame), nearest first, that first frame included."""
    if extractor.split is None or not extractor.islands.islands:
        return []
    probe = copy.deepcopy(extractor)
    below = list(below)
    out = []
    for level_mm, frame in above:
        where = f"frame at level {level_mm:g} mm"
        check_image(frame, extractor.width, extractor.height, where)
        probe.lower.frames = below[: max(1, len(extractor.lower.frames))]  # as many as it used
        read = probe.next_tiles()
        g = probe.grid
        for island in probe.islands.islands:  # the tiles of the part below, not just its edge
            x, y, w, h = cv2.boundingRect(island)
            t = ((np.array([[x, y], [x + w, y + h]]) - (g.ox, g.oy)) // g.tile).astype(int)
            read[max(0, t[0, 1]) : t[1, 1] + 1, max(0, t[0, 0]) : t[1, 0] + 1] = True
        try:
            wl = probe.read_tiles(frame, level_mm, read, where)
        except NoPartError:
            break
        out.append(wl)
        below.insert(0, (level_mm, frame))
    return out
