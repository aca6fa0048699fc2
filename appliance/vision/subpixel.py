"""Sub-pixel waterline points: the grey-level crossing along each contour normal.

A pixel contour of the binary image is only good to about a third of a pixel.
The anti-aliased grey levels know better: along the normal through each
contour pixel the intensity climbs from the local ink level to the local part
level, and the waterline is where it passes half-way. Any line that crosses
the edge meets it at a point of the edge, so a normal that is a little off
costs nothing to first order.

Only 2*half+1 bilinear samples per contour pixel are read, in Q8 fixed point
from the 8-bit median-filtered image; levels are taken locally at both ends
of each profile, so vignetting (a slow drift of both levels) does not move
the crossing.
"""
from __future__ import annotations

import numpy as np

Q = 8                      # fractional bits of the fixed-point samples
ONE = 1 << Q


def normals(contour: np.ndarray, reach: int = 2) -> np.ndarray:
    """Unit normals of a closed pixel chain from the chord between i-reach and i+reach."""
    t = np.roll(contour, -reach, axis=0) - np.roll(contour, reach, axis=0)
    t = t.astype(np.float32)
    n = np.column_stack([t[:, 1], -t[:, 0]])
    length = np.hypot(n[:, 0], n[:, 1])
    length[length == 0] = 1.0
    return n / length[:, None]


def sample_q8(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of an 8-bit image at float positions, as int32 in units of 1/256 grey."""
    h, w = img.shape
    flat = img.reshape(-1) if img.flags.c_contiguous else img.ravel()
    x = np.clip(x, 0, w - 1.001)
    y = np.clip(y, 0, h - 1.001)
    x0 = x.astype(np.int32)
    y0 = y.astype(np.int32)
    fx = ((x - x0) * ONE).astype(np.int32)
    fy = ((y - y0) * ONE).astype(np.int32)
    i = y0 * w + x0
    p00 = flat.take(i).astype(np.int32)
    p01 = flat.take(i + 1).astype(np.int32)
    p10 = flat.take(i + w).astype(np.int32)
    p11 = flat.take(i + (w + 1)).astype(np.int32)
    top = p00 * (ONE - fx) + p01 * fx
    bottom = p10 * (ONE - fx) + p11 * fx
    return (top * (ONE - fy) + bottom * fy) >> Q


def refine(img: np.ndarray, contour: np.ndarray, threshold: float, half: int = 4,
           min_contrast: float = 20.0):
    """Sub-pixel points (M, 2) (u, v) and the indices of the contour pixels they came from.

    `threshold` is the global ink/part split: a profile whose dark end is above it
    (glare on the ink beside the part) or whose bright end is below it (a
    shadow, a speck on the part) has no trustworthy mid-level and is dropped
    rather than allowed to bend the line.
    """
    c = contour.reshape(-1, 2).astype(np.float32)
    n = normals(contour.reshape(-1, 2))
    s = np.arange(-half, half + 1, dtype=np.float32)
    x = c[:, :1] + n[:, :1] * s
    y = c[:, 1:] + n[:, 1:] * s
    p = sample_q8(img, x, y).astype(np.float32) * (1.0 / ONE)
    a = 0.5 * (p[:, 0] + p[:, 1])
    b = 0.5 * (p[:, -1] + p[:, -2])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    mid = 0.5 * (a + b)
    d = p - mid[:, None]
    d0, d1 = d[:, :-1], d[:, 1:]
    crosses = (d0 * d1 <= 0) & (d0 != d1)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(crosses, d0 / (d0 - d1), np.nan)
    where = s[:-1] + frac
    # the crossing nearest where the binary edge is: half a pixel from the
    # contour pixel (a part pixel) towards the dark end of the profile
    dist = np.where(crosses, np.abs(where + 0.5 * np.sign(b - a)[:, None]), np.inf)
    j = np.argmin(dist, axis=1)
    rows = np.arange(len(c))
    t = where[rows, j]
    ok = (np.isfinite(dist[rows, j]) & (hi - lo >= min_contrast)
          & (lo < threshold) & (hi >= threshold) & (np.abs(t) <= half - 1.5))
    t = t[ok]
    pts = np.column_stack([c[ok, 0] + n[ok, 0] * t, c[ok, 1] + n[ok, 1] * t]).astype(np.float64)
    return pts, np.nonzero(ok)[0]
