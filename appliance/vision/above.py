"""The frames just above the first one that showed the part, read again.

A top comes out of the ink as a sliver or a speck, too thin or faint for a frame on
its own to tell from noise (the scan's first frames also teach the threshold and the
colour test). Read with what the frame below taught - its channel, threshold, colour
test - over the tiles of its part, and confirmed by the frames below, the sliver is
found; then the frame above that, over the sliver's tiles, until one shows nothing.
A sliver blurred below that threshold is read with a split of its own (faint_split).
The extractor is copied for this and left as it was.
"""

from __future__ import annotations

import copy

import cv2
import numpy as np

from .frames import NoPartError, channel_view, check_image, otsu_split
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
        learned = probe.split
        faint = faint_split(probe, frame)
        probe.split, probe.faint = faint or learned, faint is not None
        try:
            wl = probe.read_tiles(frame, level_mm, read, where)
        except NoPartError:
            break
        finally:
            probe.split, probe.faint = learned, False
        if faint is not None:
            # the frame above this one is confirmed by the sliver as it was read here
            probe.lower.mask(float(level_mm), frame, probe._ch, faint.threshold, probe.hue)
        out.append(wl)
        below.insert(0, (level_mm, frame))
    return out


def faint_split(probe, frame):
    """The split of `frame` inside the part the lower frames show, when it finds the top
    fainter than the threshold the scan learned; else None.

    A top that is a dim face (turned from the lamp, just over the threshold once it is wide)
    comes out as a sliver a few pixels wide that the blur keeps under the threshold: one
    harsh render's summit peaked at 58-75 grey in two frames against a threshold of 76, and
    came out 2 mm low. Inside the part of the lower frames there is only ink and the top
    coming out of it, so the split learned there sees the sliver that the whole tank's does
    not. Only a split that keeps the extractor's minimum contrast is used."""
    learned = probe.split
    inside = None
    for level, lower in probe.lower.frames:
        m = probe.lower.mask(level, lower, probe._ch, learned.threshold, probe.hue)
        inside = m if inside is None else cv2.bitwise_and(inside, m)
    if inside is None or not cv2.countNonZero(inside):
        return None
    x, y, w, h = cv2.boundingRect(inside)
    main = np.ascontiguousarray(channel_view(frame[y : y + h, x : x + w], probe._ch))
    smooth = cv2.medianBlur(main, 3)
    hist = cv2.calcHist([smooth], [0], inside[y : y + h, x : x + w], [256], [0, 256]).ravel()
    split = otsu_split(hist)
    mc = probe.options["min_contrast"]
    if split.contrast < mc or split.separability < 0.6 or split.threshold >= learned.threshold:
        return None
    return split
