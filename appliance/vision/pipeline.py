"""The frame pipeline: one 8-bit frame in, the sub-pixel waterline in mm out.

    frame (BGR/gray, uint8)
      -> one channel (the one that best separates part from dark-blue ink)
      -> 3x3 median (salt-and-pepper, sensor noise)        uint8
      -> threshold from this frame's histogram, 30 % of    uint8 0/255
         the way from the flat ink to the part, and a
         colour test (glare is lamp light on blue ink)
      -> contours with topology (outer boundaries, holes)  findContours RETR_CCOMP
      -> drop specks, glare and islands that cannot be real
      -> grey-level crossing along each contour normal     Q8 fixed point, band pixels only
         (colour-difference crossing where glare drowns
         the grey edge; speck bumps dropped)
      -> undistort the points (not the frame), homography  mm on the liquid plane

The first frame finds the part on a 1-in-4 sample of the region of interest
and reads only a band of tiles around that outline. After that only a band
of tiles around the last waterline is read, plus a sparse 1-in-16 lattice
over the rest that catches a new island or a flood; if the new waterline
reaches the edge of the band the frame is simply read again in full. So a
scan costs little more than reading the band, and never silently loses a
piece of the part (a new peak shows once it is ~16 px across).

What a contour that appears in one frame and not the next means. Across a
scan the part above the liquid is nested: at a lower level it contains what
stood out at a higher level (the part is seen from above, as a height map).
So an island that appears while the liquid *rises*, away from everything that
stood out before, cannot be part: it is glare, a bubble or a floating speck,
and is dropped. One that appears while the liquid falls is a new peak coming
out, and is kept if it is big enough to be more than a speck. An island that
vanishes while the liquid falls means last frame's was spurious; that is
recorded in `events` (the caller may drop it from the slice stack).

Exposure is monotone, and that is what keeps a bright thing that comes and goes
out of the part. Seen from above, a ray that meets the part above the liquid at
level L still meets it at every lower level: a pixel that shows part at L shows
part in every lower frame. Glare that drifts and flickers, a bubble, a speck
float on the ink and move on. So `extract` may be given the next lower frames
(`below`, nearest first; process.extract_waterlines reads two ahead): a pixel
counts as part only if it is part-like in each of them too (the same threshold
and colour test, without the glare cut, grown by a pixel for the stage's play).
Only 8-bit masks of those frames are kept, one per frame.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import SettingError
from .band import TileGrid
from .camera import CameraModel
from .frames import (
    AllPartError,
    FrameError,
    Hue,
    NoPartError,
    Split,
    best_channel,
    check_frame,
    glare_cut,
    histogram,
    hue_split,
    otsu_split,
    part_mask,
    towards_ink,
)
from .subpixel import bumps, refine, refine_colour
from .types import Waterline, signed_area

__all__ = ["WaterlineExtractor", "FrameError", "NoPartError", "AllPartError", "Event"]


@dataclass
class Event:
    level_mm: float
    kind: str  # "rejected-island", "vanished-island", "full-frame"
    detail: str


@dataclass
class _Loop:
    pixels: np.ndarray  # (N, 2) int32 contour pixels (u, v)
    hole: bool
    parent: int  # index of the outer loop a hole belongs to, else -1
    grey: float = 1.0  # fraction of its pixels placed by the grey-level step


class WaterlineExtractor:
    """Stateful per-scan extractor; call `.extract(frame, level_mm)` for every frame.

    Options (all keyword):
      channel: "auto" (chosen on the first frame), 0, 1 or 2 (B, G, R);
      roi: (x0, y0, x1, y1) pixels of the tank in the frame (default: the frame);
      band: read only a band around last frame's waterline (default True);
      band_px: half-width of that band in pixels (default 13, ~1 mm);
      tile_px: tile side of the band (default 24);
      min_area_px: smallest island or hole kept, pixels (default 60);
      min_new_island_px: smallest island kept that is not connected to the
        part of the previous frame (default 400; min_area_px when lower frames confirm it);
      min_contrast: smallest part/ink grey-level difference trusted (default 24);
      half_width: samples each side of the contour along the normal (default 4);
      threshold_fraction: where the part/ink threshold sits between the ink and
        the part levels (default 0.3: near the flat ink, below shaded part faces);
      no_part: "raise" (default: NoPartError) or "empty" (an empty Waterline) for
        a frame with no part above the liquid - a scan's top frames are like that.
    """

    def __init__(self, camera: CameraModel, **options):
        self.camera = camera
        self.width, self.height = int(camera.width), int(camera.height)
        opts = dict(
            channel="auto",
            roi=None,
            band=True,
            band_px=13,
            tile_px=24,
            min_area_px=60,
            min_new_island_px=400,
            min_contrast=24,
            half_width=4,
            threshold_fraction=0.3,
            no_part="raise",
        )
        unknown = set(options) - set(opts)
        if unknown:
            raise SettingError(
                "vision", f"unknown WaterlineExtractor option(s): {', '.join(sorted(unknown))}"
            )
        opts.update(options)
        self.options = opts
        if opts["no_part"] not in ("raise", "empty"):
            raise SettingError("vision.no_part", f"must be 'raise' or 'empty', got {opts['no_part']!r}")
        self.roi = self._check_roi(opts["roi"])
        self.grid = TileGrid(self.roi, int(opts["tile_px"]), apron=1)
        self.channel = None if opts["channel"] == "auto" else int(opts["channel"])
        # full-size 8-bit buffers reused for every frame: the median-filtered
        # channel (sampled by the sub-pixel step) and the binary part mask
        self._smooth = np.zeros((self.height, self.width), np.uint8)
        self._binary = np.zeros((self.height, self.width), np.uint8)
        self._bufs = {}
        self._decimated = None
        self.hue: Hue | None = None  # colour test against glare, learned on the first frame showing it
        self.reset()

    # -- state -----------------------------------------------------------------

    def reset(self):
        """Forget the previous frame (the next one is read in full)."""
        self.split: Split | None = None
        self.glare_cut = 256
        self._band = None  # (ny, nx) bool tiles to read next frame
        self._islands = []  # previous frame's outer loops, pixel contours
        self._level = None
        self.events: list[Event] = []
        self.last_mode = None  # "coarse", "band" or "full": how the last frame was read
        self.outline = []  # the last frame's kept loops: (pixel contour, is a hole)
        self._below = []  # the next lower frames, (level, frame)
        self._support_masks = {}  # level -> 0/255 part-like mask of that frame (grown 1 px)
        self._cut = None  # (box, mask): where this frame's part was cut back by them

    LATTICE = 16  # px between the samples that watch the rest of the tank

    def _check_roi(self, roi):
        if roi is None:
            return (0, 0, self.width, self.height)
        x0, y0, x1, y1 = (int(v) for v in roi)
        if not (0 <= x0 < x1 <= self.width and 0 <= y0 < y1 <= self.height) or x1 - x0 < 16 or y1 - y0 < 16:
            raise SettingError(
                "vision.roi", f"{roi!r} is not a rectangle inside the {self.width}x{self.height} frame"
            )
        return (x0, y0, x1, y1)

    # -- the frame ---------------------------------------------------------------

    def extract(self, frame: np.ndarray, level_mm: float, below=()) -> Waterline:
        """The waterline of `frame`. `below`: the frames of the next lower levels as
        (level_mm, frame) pairs, nearest first; a pixel is part only if they agree."""
        cut = self.glare_cut
        self.outline = []
        self._cut = None
        self._below = [(float(lv), f) for lv, f in below]
        for lv in list(self._support_masks):
            if lv not in {b[0] for b in self._below}:
                del self._support_masks[lv]
        try:
            return self._extract(frame, level_mm)
        except NoPartError:
            # what looked brightest in a frame without the part says nothing about
            # the part's top: keep the glare cut learned with the part in view
            self.glare_cut = cut
            if self.options["no_part"] == "empty":
                return Waterline(float(level_mm), [])
            raise

    def _extract(self, frame, level_mm):
        where = f"frame at level {level_mm:g} mm"
        check_frame(frame, self.width, self.height, where)
        self._decimated = None
        if self.channel is None:
            self.channel = best_channel(
                self._sample(frame, 4, all_channels=True), self.options["min_contrast"]
            )
            if self.channel is not None and self.split is not None:
                self._learn(frame, where)  # the colour test needs the channel: learn it now
        loops = None
        if self._band is not None and self._band.any() and self.options["band"]:
            loops = self._read_band(frame, level_mm, where)
        elif self.options["band"]:
            loops = self._read_coarse(frame, level_mm, where)
        if loops is None:
            loops = self._read_full(frame, level_mm, where)
        return self._finish(loops, level_mm, where)

    @property
    def _ch(self):
        return 2 if self.channel is None else self.channel  # red until a frame shows two classes

    def _sample(self, frame, step, all_channels=False):
        """A decimated copy of the tank: one strided read of the frame, shared by the checks."""
        if self._decimated is None:
            x0, y0, x1, y1 = self.roi
            self._decimated = np.ascontiguousarray(frame[y0 + 2 : y1 : 4, x0 + 2 : x1 : 4])
        sub = self._decimated[:: step // 4, :: step // 4]
        if sub.ndim == 3 and not all_channels:
            sub = sub[:, :, min(self._ch, sub.shape[2] - 1)]
        return sub

    def _buf(self, name, shape):
        b = self._bufs.get(name)
        if b is None or b.shape != shape:
            b = self._bufs[name] = np.empty(shape, np.uint8)
        return b

    def _plane(self, frame, y0, y1, x0, x1, channel=None, name="main"):
        """One channel of a rectangle, into a reused contiguous buffer."""
        if frame.ndim == 2:
            return frame[y0:y1, x0:x1]
        c = self._ch if channel is None else channel
        return cv2.extractChannel(
            frame[y0:y1, x0:x1], min(c, frame.shape[2] - 1), self._buf(name, (y1 - y0, x1 - x0))
        )

    def _apply_hue(self, main, other, binary, name):
        """binary &= (other - main <= cut) & (other < clip): glare is ink, not part."""
        if self.hue is None:
            return binary
        diff = cv2.subtract(other, main, dst=self._buf(name, main.shape))
        cv2.threshold(diff, self.hue.cut, 255, cv2.THRESH_BINARY_INV, diff)
        cv2.bitwise_and(binary, diff, binary)
        if self.hue.clip < 256:
            cv2.threshold(other, self.hue.clip - 1, 255, cv2.THRESH_BINARY_INV, diff)
            cv2.bitwise_and(binary, diff, binary)
        return binary

    def _learn(self, frame, where):
        """Channel levels, threshold and (once) the glare colour test, from the 1-in-4 sample.

        Returns the sample's main channel, its not-glare mask (or None) and the split.
        Glare pixels are left out of the histogram: big highlights on the ink
        would otherwise make a third class that blurs the ink/part split.
        """
        dec = self._sample(frame, 4, all_channels=True)
        main = np.ascontiguousarray(self._channel_view(dec, self._ch))
        hist = histogram(main)
        if self.hue is None and dec.ndim == 3 and self.channel is not None:
            self.hue = hue_split(dec[::2, ::2], self.channel, self._split(hist))
        not_glare = None
        if self.hue is not None:
            not_glare = self._not_glare(np.ascontiguousarray(dec[:, :, self.hue.other]), main)
            hist = self._glare_free(hist, main, not_glare)
        split = self._split(hist)
        self._check_split(split, where)
        self.split = split
        self.glare_cut = glare_cut(hist, split)
        return main, not_glare, split

    @staticmethod
    def _glare_free(hist, main, not_glare):
        """The histogram as if every blue pixel (ink, with or without glare on it) were plain ink.

        Big highlights on the ink would otherwise make a third class between ink
        and part and drag Otsu's split. Blue pixels count at the ink level: the
        lower quartile of their grey levels (glare only ever brightens).
        """
        ok = cv2.calcHist([main], [0], not_glare, [256], [0, 256]).ravel()
        blue = hist - ok
        n = blue.sum()
        if n > 0:
            ink = int(np.searchsorted(np.cumsum(blue), 0.25 * n))
            ok[ink] += n
        return ok

    def _not_glare(self, other, main):
        """255 where (other - main) <= cut: not the ink's blue, so not ink or glare on it."""
        ok = cv2.threshold(cv2.subtract(other, main), self.hue.cut, 255, cv2.THRESH_BINARY_INV)[1]
        if self.hue.clip < 256:
            cv2.bitwise_and(ok, cv2.threshold(other, self.hue.clip - 1, 255, cv2.THRESH_BINARY_INV)[1], ok)
        return ok

    def _split(self, hist):
        return towards_ink(otsu_split(hist), self.options["threshold_fraction"])

    def _check_split(self, split: Split, where):
        """Refuse a frame whose histogram has no ink/part split (all ink, all part, blank)."""
        mc = self.options["min_contrast"]
        two_classes = (
            split.separability >= 0.75 and split.contrast >= mc and 1e-4 < split.part_fraction < 0.995
        )
        if two_classes:
            return
        mean = split.ink * (1 - split.part_fraction) + split.part * split.part_fraction
        if not 0 < split.part_fraction < 1:
            mean = split.part if split.part_fraction >= 1 else split.ink
        if mean < (0.5 * (self.split.ink + self.split.part) if self.split else 100):
            raise NoPartError(where, "all ink: no part above the liquid at this level")
        raise AllPartError(
            where, "no ink in view: the part fills the frame (or the frame is blank/overexposed)"
        )

    def _read_full(self, frame, level_mm, where):
        self.last_mode = "full"
        split = self._learn(frame, where)[2]
        x0, y0, x1, y1 = self.roi
        smooth = self._smooth[y0:y1, x0:x1]
        main = self._plane(frame, y0, y1, x0, x1)
        cv2.medianBlur(main, 3, smooth)
        binary = part_mask(smooth, split, self.glare_cut, self._binary[y0:y1, x0:x1])
        if self.hue is not None:
            other = self._plane(frame, y0, y1, x0, x1, self.hue.other, "other")
            self._apply_hue(main, other, binary, "diff")
        self._confirm(self.roi)
        read = np.ones(self.grid.shape, bool)
        return self._loops(frame, self.roi, level_mm, read, full=True)

    def _read_coarse(self, frame, level_mm, where):
        """First frame: find the part on the 1-in-4 sample, then read only a band around it.

        The kept binary image gets the coarse labels (blown up 4x) everywhere,
        and the band read overwrites them where the waterline is. If the fine
        waterline leaves that band the caller reads the whole tank.
        """
        x0, y0, x1, y1 = self.roi
        main, not_glare, split = self._learn(frame, where)
        smooth = cv2.medianBlur(main, 3)
        coarse = part_mask(smooth, split, self.glare_cut)
        if not_glare is not None:
            cv2.bitwise_and(coarse, not_glare, coarse)
        # the kept binary image: the coarse part outlines drawn filled at full
        # size (holes too), a few pixels off at worst; the band read replaces
        # the pixels near the waterline
        contours, hier = cv2.findContours(coarse, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
        big = self._binary[y0:y1, x0:x1]
        big.fill(0)
        band = np.zeros(self.grid.shape, bool)
        if hier is None:
            return None
        scaled = [c * 4 + 2 for c in contours]
        cv2.drawContours(big, scaled, -1, 255, cv2.FILLED, hierarchy=hier)
        min_len = max(8, int(np.sqrt(self.options["min_area_px"])))
        for c in scaled:
            if len(c) * 4 >= min_len:
                # chain points 4 to 5.7 px apart: 3 px more margin covers the gaps
                pts = c.reshape(-1, 2).astype(np.float64) + (x0, y0)
                self.grid.mark(band, pts, self.options["band_px"] + 6 + 3, thin=False)
        if not band.any():
            return None
        return self._read_band(frame, level_mm, where, band, lattice=False, mode="coarse")

    def _read_band(self, frame, level_mm, where, band=None, lattice=True, mode="band", learn=True):
        """Read the band tiles (+ tiles where the sparse lattice saw a change); None: read in full.
        With `learn` False the threshold is the one already learned, however little part there is."""
        self.last_mode = mode
        grid = self.grid
        band = self._band if band is None else band
        read = self._lattice_changes(frame, band, where) if lattice else band
        ty, tx = np.nonzero(read)
        if len(ty) == 0:
            return None
        strip = grid.gather(self._channel_view(frame, self._ch), ty, tx)
        smooth = cv2.medianBlur(strip, 3)
        not_glare = None
        if self.hue is not None:
            not_glare = self._not_glare(grid.gather(self._channel_view(frame, self.hue.other), ty, tx), strip)
        # every other row is plenty for the statistics of ~10^5 band pixels
        hist = cv2.calcHist([smooth[::2]], [0], None, [256], [0, 256]).ravel()
        if not_glare is not None:
            hist = self._glare_free(hist, smooth[::2], not_glare[::2])
        split = self._split(hist) if learn else self.split
        mc = self.options["min_contrast"]
        if learn and (split.separability < 0.6 or split.contrast < mc):
            return None  # the band lost the edge: read everything
        self.split = split
        # The glare cut stays as the whole-tank sample set it - the band is where glare
        # next to the part is, the worst place to learn the part's top - unless the colour
        # test has taken the glare out of the band's histogram: then a face brighter than
        # the cut is part coming out of the ink (a sliver along a rim the lattice misses),
        # and the cut only ever rises to take it in.
        if not_glare is not None and learn:
            self.glare_cut = max(self.glare_cut, glare_cut(hist, split))
        binary = part_mask(smooth, split, self.glare_cut)
        if not_glare is not None:
            cv2.bitwise_and(binary, not_glare, binary)
        grid.scatter(smooth, self._smooth, ty, tx)
        grid.scatter(binary, self._binary, ty, tx)
        rows, cols = np.nonzero(read.any(axis=1))[0], np.nonzero(read.any(axis=0))[0]
        T = grid.tile
        box = (
            grid.ox + cols[0] * T,
            grid.oy + rows[0] * T,
            grid.ox + (cols[-1] + 1) * T,
            grid.oy + (rows[-1] + 1) * T,
        )
        self._confirm(box)
        return self._loops(frame, box, level_mm, read, full=False)

    # -- monotone exposure: what the lower frames confirm --------------------------------

    def read_above(self, above, below=()) -> list[Waterline]:
        """The frames just above the first one that showed the part, read again.

        A top comes out of the ink as a sliver or a speck, too thin or faint for a frame on
        its own to tell from noise (the scan's first frames also teach the threshold and the
        colour test). Read with what the frame below taught - its channel, threshold, colour
        test - over the tiles of its part, and confirmed by the frames below, the sliver is
        found; then the frame above that, over the sliver's tiles, until one shows nothing.

        above: (level_mm, frame) pairs going up, nearest first; below: the frames below the
        first one that showed the part, (level_mm, frame), nearest first, that one included.
        Returns the waterlines found, nearest first. This extractor is left as it was.
        """
        if self.split is None or not self._islands:
            return []
        probe = copy.deepcopy(self)
        below = list(below)
        out = []
        for level_mm, frame in above:
            where = f"frame at level {level_mm:g} mm"
            check_frame(frame, self.width, self.height, where)
            probe.outline = []
            probe._decimated = None
            probe._below = [
                (float(lv), f) for lv, f in below[: max(1, len(self._below))]
            ]  # as many as it used
            read = probe._band.copy()
            g = probe.grid
            for island in probe._islands:  # the tiles of the part below, not just its edge
                x, y, w, h = cv2.boundingRect(island)
                t = ((np.array([[x, y], [x + w, y + h]]) - (g.ox, g.oy)) // g.tile).astype(int)
                read[max(0, t[0, 1]) : t[1, 1] + 1, max(0, t[0, 0]) : t[1, 0] + 1] = True
            try:
                loops = probe._read_band(
                    frame, level_mm, where, band=read, lattice=False, mode="above", learn=False
                )
                wl = probe._finish(loops or [], level_mm, where)
            except NoPartError:
                break
            out.append(wl)
            below.insert(0, (level_mm, frame))
        return out

    def _confirm(self, box):
        """Keep as part, inside `box`, only pixels the next lower frames show part-like too."""
        self._cut = None
        if not self._below or self.split is None:
            return
        x0, y0, x1, y1 = box
        binary = self._binary[y0:y1, x0:x1]
        before = binary.copy()
        for level, frame in self._below:
            cv2.bitwise_and(binary, self._support(level, frame)[y0:y1, x0:x1], binary)
        cut = cv2.subtract(before, binary)
        if cv2.countNonZero(cut):
            # the contour along a cut follows the lower frames' part, not an edge of this
            # one: its pixels (and their neighbours) give no waterline points
            self._cut = (box, cv2.dilate(cut, np.ones((3, 3), np.uint8)))

    def _uncut(self, pixels):
        """True for contour pixels that are not on a cut made by _confirm."""
        if self._cut is None:
            return np.ones(len(pixels), bool)
        (x0, y0, x1, y1), cut = self._cut
        u, v = pixels[:, 0] - x0, pixels[:, 1] - y0
        inside = (u >= 0) & (u < x1 - x0) & (v >= 0) & (v < y1 - y0)
        keep = np.ones(len(pixels), bool)
        keep[inside] = cut[v[inside], u[inside]] == 0
        return keep

    def _support(self, level, frame):
        """Where a lower frame may show part: at or above this scan's threshold and not the ink's
        blue (the glare cut is left out: a face may be brighter there), grown by one pixel.
        Full frame, 0/255, computed once per frame with the threshold known when it is first asked."""
        mask = self._support_masks.get(level)
        if mask is None:
            x0, y0, x1, y1 = self.roi
            mask = np.zeros((self.height, self.width), np.uint8)
            main = self._plane(frame, y0, y1, x0, x1, name="support")
            part = cv2.threshold(cv2.medianBlur(main, 3), self.split.threshold - 1, 255, cv2.THRESH_BINARY)[1]
            if self.hue is not None:
                other = self._plane(frame, y0, y1, x0, x1, self.hue.other, "support-other")
                blue = cv2.subtract(other, main, dst=self._buf("support-diff", main.shape))
                cv2.threshold(blue, self.hue.cut, 255, cv2.THRESH_BINARY_INV, blue)
                cv2.bitwise_and(part, blue, part)
            cv2.dilate(part, np.ones((3, 3), np.uint8), mask[y0:y1, x0:x1])
            self._support_masks[level] = mask
        return mask

    @staticmethod
    def _channel_view(frame, c):
        return frame if frame.ndim == 2 else frame[:, :, min(c, frame.shape[2] - 1)]

    def _lattice_changes(self, frame, band, where):
        """Tiles off the band where a sparse lattice of the new frame disagrees with the kept binary.

        One strided read of every 16th pixel of every 16th row (12 k pixels):
        enough to see a new peak come out or the part flood once it is a mm
        or so across, far cheaper than reading the tank.

        The glare cut was learned from the faces out of the ink when it was: a
        face turned to the lamp that comes out later can be brighter than all of
        them (sample 4's corner: 200 DN against 85 before it). Lattice points
        above the cut (that pass the colour test, if there is one) may be such a
        face: the cut is learned again from the whole tank's sample, as on the
        first frame, before anything is decided with it (else a new face stays
        "ink" in every later frame).
        """
        g = self.grid
        D = self.LATTICE
        x0, y0, x1, y1 = g.covered
        lat = np.ascontiguousarray(frame[y0 + D // 2 : y1 : D, x0 + D // 2 : x1 : D])
        main = self._channel_view(lat, self._ch)
        now = cv2.medianBlur(np.ascontiguousarray(main), 3)
        part = now >= self.split.threshold
        if self.hue is not None:
            other = np.ascontiguousarray(lat[:, :, self.hue.other])
            part &= (cv2.subtract(other, main) <= self.hue.cut) & (other < self.hue.clip)
        if self.glare_cut < 256 and np.count_nonzero(part & (now >= self.glare_cut)) >= 2:
            self._learn(frame, where)
        part &= now < self.glare_cut
        if self._below and self.split is not None:
            # where the lower frames show part, it is about to come out: a thin ridge shows
            # here first, between the lattice's rows, so read there now
            coming = np.ones(part.shape, bool)
            for level, lower in self._below:
                coming &= self._support(level, lower)[y0 + D // 2 : y1 : D, x0 + D // 2 : x1 : D] > 0
            part |= coming
        changed = part != (self._binary[y0 + D // 2 : y1 : D, x0 + D // 2 : x1 : D] > 0)
        changed[0, :] = changed[-1, :] = False  # median borders of the lattice are not trusted
        changed[:, 0] = changed[:, -1] = False
        cy, cx = np.nonzero(changed)
        out = band.copy()
        if len(cy):
            pts = np.column_stack([x0 + D // 2 + cx * D, y0 + D // 2 + cy * D]).astype(np.float64)
            off = ~band[
                ((pts[:, 1] - g.oy) // g.tile).astype(np.intp), ((pts[:, 0] - g.ox) // g.tile).astype(np.intp)
            ]
            g.mark(out, pts[off], g.tile)
        return out

    # -- contours ------------------------------------------------------------------

    def _loops(self, frame, box, level_mm, read, full):
        x0, y0, x1, y1 = box
        contours, hierarchy = cv2.findContours(
            self._binary[y0:y1, x0:x1], cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE, offset=(x0, y0)
        )
        loops = self._filter(contours, hierarchy, level_mm)
        refined = []
        half = self.options["half_width"]
        for lp in loops:
            pts, grey = self._refine(frame, lp.pixels, self._uncut(lp.pixels))
            for _ in range(2):  # a bump's tip shows once its flanks are gone
                pts = pts[~bumps(pts)]
            refined.append(pts)
            lp.grey = grey
        loops, refined = self._drop_glare_islands(loops, refined, level_mm)
        if not full:
            # every point and its sampling reach must lie in tiles read this frame
            edge = np.vstack([lp.pixels for lp in loops]) if loops else np.zeros((0, 2))
            if not self.grid.all_marked(read, edge.astype(np.float64), half + 2):
                self.events.append(Event(level_mm, "full-frame", "waterline left the band"))
                return None
        self._remember(loops, level_mm)
        return [(lp, pts) for lp, pts in zip(loops, refined) if len(pts) >= 8]

    def _drop_glare_islands(self, loops, refined, level_mm):
        """An island whose whole edge is against glare-lit ink is a highlight, not part.

        A clipped highlight's near-white rim is not blue and passes the colour
        test; but nowhere along its edge is there plain dark ink, so (almost)
        none of its points come from the grey-level step. A real island with
        a highlight beside it keeps plain ink along most of its edge, and one
        that continues an island of the previous frame is kept whatever the glare.
        """
        bad = {
            i
            for i, lp in enumerate(loops)
            if not lp.hole
            and lp.grey < 0.25
            and not (self._islands and self._connected(lp.pixels.reshape(-1, 1, 2)))
        }
        if not bad:
            return loops, refined
        for _ in bad:
            self.events.append(Event(level_mm, "rejected-island", "edged by glare all round"))
        keep = [i for i, lp in enumerate(loops) if i not in bad and not (lp.hole and lp.parent in bad)]
        return [loops[i] for i in keep], [refined[i] for i in keep]

    def _refine(self, frame, pixels, keep):
        """Sub-pixel points of one contour in contour order (see subpixel.py), and the
        fraction of its pixels the grey-level step placed (the rest: colour, or none).
        Only pixels where `keep` holds give points."""
        half, mc = self.options["half_width"], self.options["min_contrast"] / 2
        pts, idx = refine(self._smooth, pixels, self.split.threshold, half, mc)
        grey = len(idx) / max(1, len(pixels))
        if self.hue is not None and frame.ndim == 3 and len(idx) < len(pixels):
            missing = np.setdiff1d(np.arange(len(pixels)), idx)
            more, midx = refine_colour(
                frame, pixels, missing, self._ch, self.hue.other, self.hue.cut, half, mc
            )
            if len(midx):
                idx = np.concatenate([idx, midx])
                order = np.argsort(idx, kind="stable")
                pts, idx = np.vstack([pts, more])[order], idx[order]
        if not keep.all():
            pts = pts[keep[idx]]
        return pts, grey

    def _filter(self, contours, hierarchy, level_mm):
        """Outer boundaries and their holes, without specks, glare and impossible islands."""
        if hierarchy is None:
            return []
        hier = hierarchy.reshape(-1, 4)
        min_area = self.options["min_area_px"]
        keep = {}
        loops = []
        for i, c in enumerate(contours):
            if hier[i, 3] >= 0 or len(c) < 8:
                continue
            area = cv2.contourArea(c)
            if area < min_area or not self._plausible(c, area, level_mm):
                continue
            keep[i] = len(loops)
            loops.append(_Loop(c.reshape(-1, 2), False, -1))
        for i, c in enumerate(contours):
            parent = hier[i, 3]
            if parent in keep and len(c) >= 8 and cv2.contourArea(c) >= min_area:
                loops.append(_Loop(c.reshape(-1, 2), True, keep[parent]))
        return loops

    def _plausible(self, contour, area, level_mm):
        """Is an island allowed by the previous frame (see the module notes)?"""
        if self._level is None or not self._islands:
            return True
        if self._connected(contour):
            return True
        if level_mm > self._level:
            self.events.append(
                Event(level_mm, "rejected-island", f"{area:.0f} px island appeared while the liquid rose")
            )
            return False
        # with lower frames beside it, what is left of the island is in them too (_confirm):
        # not flotsam but a peak or ridge coming out, kept from the size of a hole
        if area < self.options["min_new_island_px"] and not self._below:
            return False
        return True

    def _connected(self, contour):
        """Does an island touch or overlap one of the previous frame's islands?"""
        pts = contour.reshape(-1, 2)
        reach = self.options["band_px"]
        x, y, w, h = cv2.boundingRect(contour)
        for prev in self._islands:
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

    def _remember(self, loops, level_mm):
        outer = [lp.pixels.reshape(-1, 1, 2) for lp in loops if not lp.hole]
        if self._level is not None and level_mm < self._level:
            for prev in self._islands:
                if not any(self._overlaps(prev, o) for o in outer):
                    self.events.append(
                        Event(
                            level_mm,
                            "vanished-island",
                            "an island of the previous frame is gone although the liquid fell",
                        )
                    )
        self._islands = outer
        self._level = level_mm
        band = np.zeros(self.grid.shape, bool)
        for lp in loops:
            self.grid.mark(band, lp.pixels.astype(np.float64), self.options["band_px"])
        self._band = band

    @staticmethod
    def _overlaps(prev, cur):
        p = (float(prev[0, 0, 0]), float(prev[0, 0, 1]))
        c = (float(cur[0, 0, 0]), float(cur[0, 0, 1]))
        return cv2.pointPolygonTest(cur, p, False) >= 0 or cv2.pointPolygonTest(prev, c, False) >= 0

    # -- pixels to mm ----------------------------------------------------------------

    def _finish(self, loops, level_mm, where):
        if not loops:
            raise NoPartError(where, "no part above the liquid (only ink, glare or specks)")
        self.outline = [(lp.pixels, lp.hole) for lp, _ in loops]
        out = []
        for lp, pts in loops:
            mm = self.camera.pixels_to_mm(pts)
            area = signed_area(mm)
            if (area < 0) != lp.hole:  # outer CCW (area > 0), holes CW
                mm = mm[::-1].copy()
            out.append(mm)
        return Waterline(float(level_mm), out)
