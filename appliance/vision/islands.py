"""Which contours of a frame may be part, given the frame before it.

What a contour that appears in one frame and not the next means. Across a
scan the part above the liquid is nested: at a lower level it contains what
stood out at a higher level (the part is seen from above, as a height map).
So an island that appears while the liquid *rises*, away from everything that
stood out before, cannot be part: it is glare, a bubble or a floating speck,
and is dropped. One that appears while the liquid falls is a new peak coming
out, and is kept if it is big enough to be more than a speck. An island that
vanishes while the liquid falls means last frame's was spurious; that is
recorded in `events` (the caller may drop it from the slice stack).

The waterline extractor (pipeline.py) keeps one IslandTracker per scan.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class Event:
    level_mm: float
    kind: str  # "rejected-island", "vanished-island", "full-frame"
    detail: str


@dataclass
class Loop:
    pixels: np.ndarray  # (N, 2) int32 contour pixels (u, v)
    hole: bool
    parent: int  # index of the outer loop a hole belongs to, else -1
    grey: float = 1.0  # fraction of its pixels placed by the grey-level step


class IslandTracker:
    """The previous frame's islands, and what they allow in the next frame.

    band_px: how near an island must come to one of the previous frame's to
    continue it; min_new_island_px: the smallest island kept that continues
    none, unless lower frames confirm it. What is refused is told in `events`.
    """

    def __init__(self, band_px: int, min_new_island_px: int, events: list[Event]):
        self.band_px = band_px
        self.min_new_island_px = min_new_island_px
        self.events = events
        self.islands: list[np.ndarray] = []  # the previous frame's outer loops, pixel contours
        self.level: float | None = None  # the previous frame's level

    def loops(self, contours, hierarchy, level_mm: float, min_area: float, confirmed: bool) -> list[Loop]:
        """Outer boundaries and their holes, without specks, glare and impossible islands.
        `confirmed`: the frame's part was confirmed by lower frames (pipeline.py)."""
        if hierarchy is None:
            return []
        hier = hierarchy.reshape(-1, 4)
        keep: dict[int, int] = {}
        loops: list[Loop] = []
        for i, c in enumerate(contours):
            if hier[i, 3] >= 0 or len(c) < 8:
                continue
            area = cv2.contourArea(c)
            if area < min_area or not self.plausible(c, area, level_mm, confirmed):
                continue
            keep[i] = len(loops)
            loops.append(Loop(c.reshape(-1, 2), False, -1))
        for i, c in enumerate(contours):
            parent = hier[i, 3]
            if parent in keep and len(c) >= 8 and cv2.contourArea(c) >= min_area:
                loops.append(Loop(c.reshape(-1, 2), True, keep[parent]))
        return loops

    def plausible(self, contour, area: float, level_mm: float, confirmed: bool) -> bool:
        """Is an island allowed by the previous frame (see the module notes)?"""
        if self.level is None or not self.islands:
            return True
        if self.connected(contour):
            return True
        if level_mm > self.level:
            self.events.append(
                Event(level_mm, "rejected-island", f"{area:.0f} px island appeared while the liquid rose")
            )
            return False
        # with lower frames beside it, what is left of the island is in them too:
        # not flotsam but a peak or ridge coming out, kept from the size of a hole
        if area < self.min_new_island_px and not confirmed:
            return False
        return True

    def connected(self, contour) -> bool:
        """Does an island touch or overlap one of the previous frame's islands?"""
        pts = contour.reshape(-1, 2)
        reach = self.band_px
        x, y, w, h = cv2.boundingRect(contour)
        for prev in self.islands:
            px, py, pw, ph = cv2.boundingRect(prev)
            if x > px + pw + reach or px > x + w + reach or y > py + ph + reach or py > y + h + reach:
                continue
            probe = (float(pts[0, 0]), float(pts[0, 1]))
            if cv2.pointPolygonTest(prev, probe, True) > -reach:
                return True
            back = (float(prev[0, 0, 0]), float(prev[0, 0, 1]))
            if cv2.pointPolygonTest(contour, back, True) > -reach:
                return True
        return False

    def drop_glare_islands(self, loops: list[Loop], refined: list, level_mm: float):
        """An island whose whole edge is against glare-lit ink is a highlight, not part.

        A clipped highlight's near-white rim is not blue and passes the colour
        test; but nowhere along its edge is there plain dark ink, so (almost)
        none of its points come from the grey-level step. A real island with
        a highlight beside it keeps plain ink along most of its edge, and one
        that continues an island of the previous frame is kept whatever the glare.
        Returns the loops and their refined points that are kept.
        """
        bad = {
            i
            for i, lp in enumerate(loops)
            if not lp.hole
            and lp.grey < 0.25
            and not (self.islands and self.connected(lp.pixels.reshape(-1, 1, 2)))
        }
        if not bad:
            return loops, refined
        for _ in bad:
            self.events.append(Event(level_mm, "rejected-island", "edged by glare all round"))
        keep = [i for i, lp in enumerate(loops) if i not in bad and not (lp.hole and lp.parent in bad)]
        return [loops[i] for i in keep], [refined[i] for i in keep]

    def remember(self, loops: list[Loop], level_mm: float) -> None:
        """This frame's islands become the previous frame's; an island of the previous frame
        that is gone although the liquid fell is told in `events`."""
        outer = [lp.pixels.reshape(-1, 1, 2) for lp in loops if not lp.hole]
        if self.level is not None and level_mm < self.level:
            for prev in self.islands:
                if not any(_overlaps(prev, o) for o in outer):
                    self.events.append(
                        Event(
                            level_mm,
                            "vanished-island",
                            "an island of the previous frame is gone although the liquid fell",
                        )
                    )
        self.islands = outer
        self.level = level_mm


def _overlaps(prev, cur) -> bool:
    p = (float(prev[0, 0, 0]), float(prev[0, 0, 1]))
    c = (float(cur[0, 0, 0]), float(cur[0, 0, 1]))
    return cv2.pointPolygonTest(cur, p, False) >= 0 or cv2.pointPolygonTest(prev, c, False) >= 0
