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

Which contours may be part, given the frame before (islands.py), and what the
next lower frames confirm of this one (support.py: exposure is monotone, so a
bright thing that comes and goes is not part), are told in their modules.
"""

from __future__ import annotations

import cv2
import numpy as np

from .above import read_above
from .band import TileGrid
from .camera import CameraModel
from .frames import (
    AllPartError,
    FrameError,
    Hue,
    NoPartError,
    Split,
    best_channel,
    channel_view,
    check_image,
    check_split,
    glare_cut,
    glare_free,
    histogram,
    hue_split,
    not_glare,
    otsu_split,
    threshold_part,
    towards_ink,
)
from .islands import Event, IslandTracker
from .options import check_roi, extractor_options
from .subpixel import bumps, more_points, refine, refine_at, refine_colour
from .support import LowerFrames, Raised
from .types import Waterline, signed_area

__all__ = ["WaterlineExtractor", "FrameError", "NoPartError", "AllPartError", "Event"]


class WaterlineExtractor:
    """Stateful per-scan extractor; call `.extract(frame, level_mm)` for every frame.

    Options (all keyword) are listed in options.py.
    """

    def __init__(self, camera: CameraModel, **options):
        self.camera = camera
        self.width, self.height = int(camera.width), int(camera.height)
        self.options = opts = extractor_options(options)
        self.roi = check_roi(opts["roi"], self.width, self.height)
        self.grid = TileGrid(self.roi, int(opts["tile_px"]), apron=1)
        self.channel = None if opts["channel"] == "auto" else int(opts["channel"])
        # full-size 8-bit buffers reused for every frame: the median-filtered
        # channel (sampled by the sub-pixel step) and the binary part mask
        self._smooth = np.zeros((self.height, self.width), np.uint8)
        self._binary = np.zeros((self.height, self.width), np.uint8)
        self._bufs: dict[str, np.ndarray] = {}
        self._decimated = None
        self.hue: Hue | None = None  # colour test against glare, learned on the first frame showing it
        self.faint = False  # reading a top's sliver with a split learned on it (above.py)
        self.reset()

    # -- state -----------------------------------------------------------------

    def reset(self):
        """Forget the previous frame (the next one is read in full)."""
        self.split: Split | None = None
        self.glare_cut = 256
        self._band = None  # (ny, nx) bool tiles to read next frame
        self.events: list[Event] = []
        self.islands = IslandTracker(self.options["band_px"], self.options["min_new_island_px"], self.events)
        self.last_mode = None  # "coarse", "band" or "full": how the last frame was read
        self.outline = []  # the last frame's kept loops: (pixel contour, is a hole)
        self.lower = LowerFrames(self.roi, (self.height, self.width), self._raised())

    def _raised(self):
        """How an edge above the ink moves between frames (support.Raised), or None when the
        option is off or the camera's pose is not known."""
        cam = self.camera
        if not self.options["raised_shores"]:
            return None
        foot = cam.centre_xy() if cam.height_mm else None
        if foot is None:
            return None
        u, v = cam.mm_to_pixels(np.array([foot], float))[0]
        return Raised((float(u), float(v)), float(cam.height_mm))

    LATTICE = 16  # px between the samples that watch the rest of the tank

    # -- the frame ---------------------------------------------------------------

    def extract(self, frame: np.ndarray, level_mm: float, below=()) -> Waterline:
        """The waterline of `frame`. `below`: the frames of the next lower levels as
        (level_mm, frame) pairs, nearest first; a pixel is part only if they agree."""
        cut = self.glare_cut
        self.outline = []
        self.lower.use(below, level_mm)
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
        check_image(frame, self.width, self.height, where)
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

    def next_tiles(self) -> np.ndarray | None:
        """A copy of the tiles the next frame is read over (the band around the last
        waterline; None before a frame showed the part)."""
        return None if self._band is None else self._band.copy()

    def read_tiles(self, frame: np.ndarray, level_mm: float, tiles: np.ndarray, where: str) -> Waterline:
        """The waterline of `frame` read over `tiles` only, with what the frames before taught
        (channel, threshold, colour test) however little part the tiles show: how above.py
        reads the frames above the first that showed the part. NoPartError when none shows."""
        self.outline = []
        self._decimated = None
        loops = self._read_band(frame, level_mm, where, band=tiles, lattice=False, mode="above", learn=False)
        return self._finish(loops or [], level_mm, where)

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

    def _learn(self, frame, where):
        """Channel levels, threshold and (once) the glare colour test, from the 1-in-4 sample.

        Returns the sample's main channel, its not-glare mask (or None) and the split.
        Glare pixels are left out of the histogram: big highlights on the ink
        would otherwise make a third class that blurs the ink/part split.
        """
        dec = self._sample(frame, 4, all_channels=True)
        main = np.ascontiguousarray(channel_view(dec, self._ch))
        hist = histogram(main)
        if self.hue is None and dec.ndim == 3 and self.channel is not None:
            self.hue = hue_split(dec[::2, ::2], self.channel, self._split(hist))
        unglared = None
        if self.hue is not None:
            unglared = not_glare(np.ascontiguousarray(dec[:, :, self.hue.other]), main, self.hue)
            hist = glare_free(hist, main, unglared)
        split = self._split(hist)
        check_split(split, self.split, self.options["min_contrast"], where)
        self.split = split
        self.glare_cut = glare_cut(hist, split)
        return main, unglared, split

    def _split(self, hist):
        return towards_ink(otsu_split(hist), self.options["threshold_fraction"])

    def _read_full(self, frame, level_mm, where):
        self.last_mode = "full"
        split = self._learn(frame, where)[2]
        x0, y0, x1, y1 = self.roi
        smooth = self._smooth[y0:y1, x0:x1]
        main = self._plane(frame, y0, y1, x0, x1)
        cv2.medianBlur(main, 3, smooth)
        binary = threshold_part(smooth, split, self.glare_cut, self._binary[y0:y1, x0:x1])
        if self.hue is not None:
            other = self._plane(frame, y0, y1, x0, x1, self.hue.other, "other")
            cv2.bitwise_and(binary, not_glare(other, main, self.hue), binary)
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
        main, unglared, split = self._learn(frame, where)
        smooth = cv2.medianBlur(main, 3)
        coarse = threshold_part(smooth, split, self.glare_cut)
        if unglared is not None:
            cv2.bitwise_and(coarse, unglared, coarse)
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
        strip = grid.gather(channel_view(frame, self._ch), ty, tx)
        smooth = cv2.medianBlur(strip, 3)
        unglared = None
        if self.hue is not None:
            unglared = not_glare(grid.gather(channel_view(frame, self.hue.other), ty, tx), strip, self.hue)
        # every other row is plenty for the statistics of ~10^5 band pixels
        hist = cv2.calcHist([smooth[::2]], [0], None, [256], [0, 256]).ravel()
        if unglared is not None:
            hist = glare_free(hist, smooth[::2], unglared[::2])
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
        if unglared is not None and learn:
            self.glare_cut = max(self.glare_cut, glare_cut(hist, split))
        binary = threshold_part(smooth, split, self.glare_cut)
        if unglared is not None:
            cv2.bitwise_and(binary, unglared, binary)
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

    def _confirm(self, box):
        """Keep as part, inside `box`, only pixels the next lower frames show part-like too."""
        if self.split is None:
            self.lower.cut = None
            return
        self.lower.confirm(self._binary, box, self._ch, self.split.threshold, self.hue)

    def read_above(self, above, below=()) -> list[Waterline]:
        """The frames just above the first one that showed the part, read again for the
        part's top (above.py). This extractor is left as it was."""
        return read_above(self, above, below)

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
        main = channel_view(lat, self._ch)
        now = cv2.medianBlur(np.ascontiguousarray(main), 3)
        part = now >= self.split.threshold
        if self.hue is not None:
            other = np.ascontiguousarray(lat[:, :, self.hue.other])
            part &= (cv2.subtract(other, main) <= self.hue.cut) & (other < self.hue.clip)
        if self.glare_cut < 256 and np.count_nonzero(part & (now >= self.glare_cut)) >= 2:
            self._learn(frame, where)
        part &= now < self.glare_cut
        if self.lower.frames and self.split is not None:
            # where the lower frames show part, it is about to come out: a thin ridge shows
            # here first, between the lattice's rows, so read there now
            coming = np.ones(part.shape, bool)
            for level, lower in self.lower.frames:
                mask = self.lower.mask(level, lower, self._ch, self.split.threshold, self.hue)
                coming &= mask[y0 + D // 2 : y1 : D, x0 + D // 2 : x1 : D] > 0
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
        loops = self.islands.loops(
            contours, hierarchy, level_mm, self.options["min_area_px"], bool(self.lower.frames)
        )
        refined = []
        half = self.options["half_width"]
        for lp in loops:
            pts, grey = self._refine(frame, lp.pixels, self.lower.uncut(lp.pixels))
            for _ in range(2):  # a bump's tip shows once its flanks are gone
                pts = pts[~bumps(pts)]
            refined.append(pts)
            lp.grey = grey
        loops, refined = self.islands.drop_glare_islands(loops, refined, level_mm)
        if not full:
            # every point and its sampling reach must lie in tiles read this frame
            edge = np.vstack([lp.pixels for lp in loops]) if loops else np.zeros((0, 2))
            if not self.grid.all_marked(read, edge.astype(np.float64), half + 2):
                self.events.append(Event(level_mm, "full-frame", "waterline left the band"))
                return None
        self.islands.remember(loops, level_mm)
        band = np.zeros(self.grid.shape, bool)
        for lp in loops:
            self.grid.mark(band, lp.pixels.astype(np.float64), self.options["band_px"])
        self._band = band
        return [(lp, pts) for lp, pts in zip(loops, refined) if len(pts) >= 8]

    def _refine(self, frame, pixels, keep):
        """Sub-pixel points of one contour in contour order (see subpixel.py), and the
        fraction of its pixels the grey-level step placed (the rest: colour, or none).
        Only pixels where `keep` holds give points."""
        half, mc = self.options["half_width"], self.options["min_contrast"] / 2
        pts, idx = refine(self._smooth, pixels, self.split.threshold, half, mc)
        grey = len(idx) / max(1, len(pixels))
        # points the grey-level step dropped: from the colour where glare drowns the grey
        # edge, from the split itself across a faint sliver (above.py)
        if self.hue is not None and frame.ndim == 3:
            pts, idx = more_points(
                pts, idx, pixels, refine_colour, frame, self._ch, self.hue.other, self.hue.cut, half, mc
            )
        if self.faint:
            pts, idx = more_points(pts, idx, pixels, refine_at, self._smooth, self.split.threshold, half)
        if not keep.all():
            pts = pts[keep[idx]]
        return pts, grey

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
