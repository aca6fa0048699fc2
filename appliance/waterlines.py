"""Every frame's waterline, read top level first: all at once, or as the frames land.

The frames are read in order of level, highest first, by one stateful extractor (it reads
a band around the last waterline, and knows the glare it has seen). Each frame is read with
the next lower ones beside it: exposure is monotone, so what is part here is part below,
and what they do not show is glare or flotsam. When the first frame to show the part comes,
the few above it are read again for the part's top as a sliver.

A daemon's processing child starts reading while the scan runs (daemon/processing.py), so
the waterlines are done when the last frame lands. It can read a frame once the frames
below it that confirm it are final; a frame the scan inserts later above one already read
(the runner refines a step, or rises above a tall part's top) changes what was read, so
`TopDownReader.read` checks that the frames read so far are still the first of the scan's
order and starts again from the top when they are not: the result is always what one read
of the whole finished scan gives.
"""

from __future__ import annotations

from collections import deque

from . import progress
from .scanfile import read_frame

CONFIRMING_FRAMES = 2  # lower frames that must agree a pixel is part (vision/pipeline.py)
REREAD_ABOVE = 3  # frames above the first showing the part read again for its top


def frames_top_down(scan):
    return sorted(scan.frames, key=lambda f: -f.level_mm)


def waterline_frames(scan) -> list:
    """The frames that can show a waterline, top level first (not those at or below level 0:
    there the base top is out of the ink)."""
    from .surface.slices import shows_waterline

    return [ref for ref in frames_top_down(scan) if shows_waterline(ref.level_mm)]


def extract_waterlines(scan):
    """Every frame's waterline, top level first."""
    return with_held_pools(scan, TopDownReader(scan).read(waterline_frames(scan), final=True))


def with_held_pools(scan, waterlines):
    """`waterlines`, or the scan read again with raised shores kept when a pocket may have
    held ink (surface/pools.py) and that read shows it did.

    Confirming part by the lower frames cuts away an edge standing above the ink with ink
    on the camera's side of it: it recedes as the part rises. A pool's far shore is such an
    edge from the frame its pocket closed down to the last, and the pool's hole went with
    it (the crater's: read ever smaller from 1105 to 110 mm², then not at all, then back).
    The ink that wets a wall up to its top edge makes the same edge for a few frames (the
    harsh ring's hole), where keeping it costs the fit (Ea 0.0487 -> 0.0528 mm): so the read
    keeping raised shores is used only for scans whose pools it confirms."""
    from .surface.perspective import Perspective
    from .surface.pools import held_pools, pools_suspected

    camera = Perspective.of(scan.camera)
    if not pools_suspected(_frames(waterlines), camera):
        return waterlines
    again = TopDownReader(scan, raised_shores=True).read(waterline_frames(scan), final=True)
    return again if held_pools(_frames(again), camera) else waterlines


def _frames(waterlines):
    return [(wl.level_mm, wl.loops) for wl in waterlines]


class TopDownReader:
    """The waterlines of a scan's frames, read in as many goes as the frames come in."""

    def __init__(self, scan, raised_shores=False):
        self.scan = scan
        self.raised_shores = raised_shores
        # the frame pairs' shifts measured as the frames were read, for the fit's registration
        # (daemon/processing_child.py measure_pairs; keyed by the slices' content)
        self.pair_memo: dict = {}
        self._start()

    def _start(self):
        from .vision.pipeline import WaterlineExtractor

        # a scan starts above the part: a frame without it is an empty waterline
        self.extractor = WaterlineExtractor(
            self.scan.camera, no_part="empty", raised_shores=self.raised_shores
        )
        self.taken: list = []  # the frames read so far (into `ahead` too), in order
        self.ahead: deque = deque()  # (level, image) of the frames below the next one
        self.out: list = []
        self.above: deque = deque(maxlen=REREAD_ABOVE)  # the last frames, while none has shown the part

    def read(self, frames: list, final: bool = False) -> list:
        """Read `frames` (waterline_frames of the scan as it is now) as far as they are known:
        with `final`, to the end; else each frame only once CONFIRMING_FRAMES frames below it
        are in `frames`. Returns the waterlines read so far, top level first."""
        if [_key(f) for f in frames[: len(self.taken)]] != [_key(f) for f in self.taken]:
            self._start()  # a frame came in above what was read: read again from the top
        last = len(frames) if final else len(frames) - CONFIRMING_FRAMES
        if final:
            progress.stage("waterlines", total=len(frames))
        for i in range(len(self.out), last):
            if final:
                progress.step(i)
            self._read_one(frames, i)
        return list(self.out)

    def finish(self, scan) -> list:
        """All of the finished scan's waterlines (process's `waterlines_of`)."""
        return with_held_pools(scan, self.read(waterline_frames(scan), final=True))

    def _read_one(self, frames, i):
        while len(self.ahead) < CONFIRMING_FRAMES + 1 and i + len(self.ahead) < len(frames):
            nxt = frames[i + len(self.ahead)]
            self.ahead.append((nxt.level_mm, read_frame(self.scan, nxt)))
            self.taken.append(nxt)
        level, frame = self.ahead.popleft()
        self.out.append(self.extractor.extract(frame, level, below=list(self.ahead)))
        if self.above and self.out[-1].loops:
            # the first frame showing the part: the ones above may show its top as a sliver
            found = self.extractor.read_above(
                list(reversed(self.above)), below=[(level, frame)] + list(self.ahead)
            )
            for k, wl in enumerate(found):
                self.out[-2 - k] = wl
        if any(wl.loops for wl in self.out):
            self.above.clear()
        else:
            self.above.append((level, frame))


def _key(ref):
    return (ref.file, ref.level_mm)
