"""Frame checks, channel choice and the lighting-adaptive threshold, all 8-bit.

The ink is dark blue: in a colour frame its red channel is nearly black while
a light part is bright in every channel, so one well-chosen channel separates
them better than a grey mix and costs only a strided read. The threshold comes
from a histogram of a decimated view of the tank (a few tens of thousands of
pixels), not of the whole frame, and saturated bins are left out so that
specular glare (clipped at 255) cannot drag it upwards.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ScanError

SATURATED = 250  # bins at or above this are glare or clipped highlights


class FrameError(ScanError):
    """A frame the waterline cannot be read from (wrong size, truncated, ...)."""


class NoPartError(FrameError):
    """No part above the liquid: all ink (or only glare and specks)."""


class AllPartError(FrameError):
    """The part fills the view: no ink, so no waterline."""


def check_image(frame, width: int, height: int, where="frame"):
    """Raise FrameError unless `frame` is an 8-bit gray/BGR(A) image of the camera size."""
    if not isinstance(frame, np.ndarray):
        raise FrameError(where, f"frame must be a numpy array, got {type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise FrameError(where, f"frame must be 8-bit, got {frame.dtype}")
    if frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] not in (1, 3, 4)):
        raise FrameError(where, f"frame must be gray or BGR, got shape {frame.shape}")
    h, w = frame.shape[:2]
    if w == width and h < height:
        raise FrameError(where, f"frame is truncated: {h} of {height} rows")
    if (w, h) != (width, height):
        raise FrameError(where, f"frame is {w}x{h}, the camera is {width}x{height}")
    # A truncated file decoded by a lenient reader ends in rows of exact zeros;
    # a real sensor never reads 0 in every channel over whole rows (black level).
    tail = frame[-max(2, height // 64) :]
    if not tail.any():
        raise FrameError(where, "frame ends in rows of zeros (truncated capture or file?)")


def channel_view(frame, channel: int):
    """A (strided) view of one channel; a gray frame is its own channel."""
    if frame.ndim == 2:
        return frame
    return frame[:, :, min(channel, frame.shape[2] - 1)]


@dataclass
class Split:
    """Two classes of a histogram: ink below `threshold`, part at or above it."""

    threshold: int
    ink: float  # mean grey level of the ink class
    part: float  # mean grey level of the part class
    part_fraction: float
    separability: float  # Otsu's between-class / total variance, 0..1
    otsu: int = -1  # Otsu's own threshold, when `threshold` was moved towards the ink

    @property
    def contrast(self):
        return self.part - self.ink


def otsu_split(hist: np.ndarray) -> Split:
    """Otsu's threshold of a 256-bin histogram, saturated bins excluded."""
    h = np.asarray(hist, np.float64)[:SATURATED]
    total = h.sum()
    if total <= 0:
        return Split(128, 0.0, 255.0, 0.0, 0.0)
    levels = np.arange(h.size, dtype=np.float64)
    w0 = np.cumsum(h)
    m0 = np.cumsum(h * levels)
    mean = m0[-1] / total
    w1 = total - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mean * w0 - m0) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = 0
    k = int(np.argmax(between))  # ink is 0..k, part k+1..
    var = float(np.dot(h, (levels - mean) ** 2) / total)
    ink = m0[k] / w0[k] if w0[k] > 0 else 0.0
    part = (m0[-1] - m0[k]) / w1[k] if w1[k] > 0 else 255.0
    sep = float(between[k] / var) if var > 0 else 0.0
    return Split(k + 1, float(ink), float(part), float(w1[k] / total), sep)


def towards_ink(split: Split, fraction: float) -> Split:
    """Move the threshold to `fraction` of the way from the ink level to the part level.

    Otsu splits the two classes by variance, and a part shaded from the lamp
    (Lambertian, down to the ambient level) spreads the part class so widely
    that its threshold can fall inside it and cut a peak's dark side off. The
    ink is flat and dark; a threshold just above it keeps every lit or shaded
    part pixel (glare is dealt with by colour, specks by size).
    """
    t = int(np.ceil(split.ink + fraction * (split.part - split.ink)))
    return Split(
        max(1, min(t, split.threshold)),
        split.ink,
        split.part,
        split.part_fraction,
        split.separability,
        split.threshold,
    )


def threshold_part(smooth: np.ndarray, split: Split, glare_cut: int, out=None):
    """0/255 binary image of the part: at or above the threshold, and below `glare_cut`.

    Specular glare on the liquid clips at the top of the range while a diffuse
    part does not; pixels at or above `glare_cut` (256 disables it) count as
    ink so that a highlight beside the part cannot bulge its waterline.
    """
    return cv2.inRange(smooth, split.threshold, glare_cut - 1, out)


def glare_cut(hist: np.ndarray, split: Split) -> int:
    """Grey level from which a pixel is too bright to be part, or 256 when the part itself clips.

    The lit part has a top level (its brightest, fully lit face); glare on the
    ink is added light and climbs past it to white. Anything a little above the
    part's 99.5th percentile is glare, so a clipped highlight and the
    near-white ring round it cannot pose as part.
    """
    h = np.asarray(hist, np.float64)
    part = h[split.threshold : SATURATED]
    if part.sum() <= 0:
        return 256
    top = split.threshold + int(np.searchsorted(np.cumsum(part), 0.995 * part.sum()))
    return 256 if top >= SATURATED - 6 else top + 6


@dataclass
class Hue:
    """A second, colour test against glare: part where (other - main) <= cut.

    Glare is the lamp's light added to the ink: it lifts every channel, so in
    the main (red) channel it can look as bright as a shaded part, but the ink
    stays much bluer than red and the light grey part does not. The saturating
    8-bit difference other - main (blue - red) separates them at any glare.
    """

    other: int
    cut: int
    clip: int = 256  # other-channel level from which a pixel is a clipped highlight


def hue_split(sample_bgr: np.ndarray, main: int, split: Split, min_gap: float = 24.0):
    """The Hue test learned from a decimated colour sample, or None (gray frames, grey ink).

    The ink's own colour is enough to start with: glare is lamp light added to
    the ink, so it stays about as much bluer than red as the ink is, while a
    light part is not blue at all. When bright pixels are present the part's
    colour is found as the less-blue of two classes among them (there may be
    more glare than part), else it is taken as neutral.
    """
    if sample_bgr.ndim == 2 or sample_bgr.shape[2] < 3:
        return None
    m = np.ascontiguousarray(sample_bgr[:, :, main])
    bright = m >= (split.otsu if split.otsu >= 0 else split.threshold)
    if (~bright).sum() < 16:
        return None
    best = None
    for c in range(3):
        if c == main:
            continue
        o = np.ascontiguousarray(sample_bgr[:, :, c])
        d = cv2.subtract(o, m)  # saturates at 0
        d_ink = float(d[~bright].mean())
        d_part = 0.0
        if bright.sum() >= 4:
            inner = otsu_split(np.bincount(d[bright], minlength=256))
            lower = (1 - inner.part_fraction) * bright.sum()
            if inner.contrast >= min_gap and lower >= 4:
                d_part = inner.ink  # (a small part among big highlights: still a class)
            elif float(d[bright].mean()) < 0.5 * d_ink:
                d_part = float(d[bright].mean())
        gap = d_ink - d_part
        if gap >= min_gap and (best is None or gap > best[0]):
            cut = int(round(d_part + 0.5 * gap))
            # Where glare clips, the ink's blue saturates first and its red
            # catches up: the clipped core is no longer blue, but it is brighter
            # in `other` than the lit part ever is. Unless the part clips too.
            part_o = o[bright & (d <= cut)]
            top = float(np.percentile(part_o, 99)) if part_o.size >= 16 else 0.0
            best = (gap, c, cut, SATURATED if top < SATURATED - 10 else 256)
    return Hue(best[1], best[2], best[3]) if best else None


def not_glare(other: np.ndarray, main: np.ndarray, hue: Hue) -> np.ndarray:
    """255 where (other - main) <= cut and other < clip: not the ink's blue, so neither ink
    nor glare on it."""
    ok = cv2.threshold(cv2.subtract(other, main), hue.cut, 255, cv2.THRESH_BINARY_INV)[1]
    if hue.clip < 256:
        cv2.bitwise_and(ok, cv2.threshold(other, hue.clip - 1, 255, cv2.THRESH_BINARY_INV)[1], ok)
    return ok


def glare_free(hist: np.ndarray, main: np.ndarray, not_glare_mask: np.ndarray) -> np.ndarray:
    """The histogram as if every blue pixel (ink, with or without glare on it) were plain ink.

    Big highlights on the ink would otherwise make a third class between ink
    and part and drag Otsu's split. Blue pixels count at the ink level: the
    lower quartile of their grey levels (glare only ever brightens).
    """
    ok = cv2.calcHist([main], [0], not_glare_mask, [256], [0, 256]).ravel()
    blue = hist - ok
    n = blue.sum()
    if n > 0:
        ink = int(np.searchsorted(np.cumsum(blue), 0.25 * n))
        ok[ink] += n
    return ok


def check_split(split: Split, before: Split | None, min_contrast: float, where) -> None:
    """Refuse a frame whose histogram has no ink/part split (all ink, all part, blank).
    `before`: the split of the frames before, which tells all ink from all part."""
    two_classes = (
        split.separability >= 0.75 and split.contrast >= min_contrast and 1e-4 < split.part_fraction < 0.995
    )
    if two_classes:
        return
    mean = split.ink * (1 - split.part_fraction) + split.part * split.part_fraction
    if not 0 < split.part_fraction < 1:
        mean = split.part if split.part_fraction >= 1 else split.ink
    if mean < (0.5 * (before.ink + before.part) if before else 100):
        raise NoPartError(where, "all ink: no part above the liquid at this level")
    raise AllPartError(where, "no ink in view: the part fills the frame (or the frame is blank/overexposed)")


def histogram(img: np.ndarray) -> np.ndarray:
    return cv2.calcHist([np.ascontiguousarray(img)], [0], None, [256], [0, 256]).ravel()


def best_channel(sample_bgr: np.ndarray, min_contrast: float = 24.0):
    """The channel in which the ink is darkest against the brightest things in view.

    The ink is dark blue, the part light grey: in the red channel the ink is
    nearly black while the part is as bright as anywhere. Scoring by the
    ink's darkness (its low percentile) rather than by a two-class split keeps
    the choice right when big highlights outnumber a small part (glare is
    brightest in blue). None when no channel has contrast (blank frame): the bright
    tail must stand min_contrast above the brightest the ink itself gets, told from its
    spread below its 20th percentile (three times that above it, 4-5 sigma of noise).
    Measured from the 20th percentile alone, a noisy camera's vignetted blank frame
    passed in blue, where the ink is brightest, and a scan read from above the part
    then found no part in any frame.
    """
    if sample_bgr.ndim == 2:
        return 0
    scores = []
    for c in range(min(3, sample_bgr.shape[2])):
        # the bright tail: a 10 mm part is 0.05 % of the frame when its top first shows
        dark, lo, hi = np.percentile(sample_bgr[:, :, c], [1, 20, 99.98])
        ink_top = lo + 3.0 * (lo - dark)
        scores.append((hi - lo) / (lo + 8.0) if hi - ink_top >= min_contrast else 0.0)
    return int(np.argmax(scores)) if max(scores) > 0 else None
