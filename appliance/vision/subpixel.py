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

Q = 8  # fractional bits of the fixed-point samples
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
    if x.min() < 0 or y.min() < 0 or x.max() >= w - 1 or y.max() >= h - 1:
        x = np.clip(x, 0, w - 1.001)
        y = np.clip(y, 0, h - 1.001)
    xq = (x * ONE).astype(np.int32)  # Q8 positions: integer part and fraction in one
    yq = (y * ONE).astype(np.int32)
    fx = xq & (ONE - 1)
    fy = yq & (ONE - 1)
    i = (yq >> Q) * w + (xq >> Q)
    p00 = flat.take(i)
    p01 = flat.take(i + 1)
    p10 = flat.take(i + w)
    p11 = flat.take(i + (w + 1))
    top = p00 * (ONE - fx) + p01 * fx  # uint8 * int32 -> int32
    bottom = p10 * (ONE - fx) + p11 * fx
    return (top * (ONE - fy) + bottom * fy) >> Q


def _profiles(contour, half, subset=None):
    c = contour.reshape(-1, 2).astype(np.float32)
    n = normals(contour.reshape(-1, 2))
    if subset is not None:
        c, n = c[subset], n[subset]
    s = np.arange(-half, half + 1, dtype=np.float32)
    return c, n, s, c[:, :1] + n[:, :1] * s, c[:, 1:] + n[:, 1:] * s


def _crossing(p, s, threshold, min_contrast, max_shift):
    """Offset along each profile where it passes half-way between its two ends, and which to trust.

    The part is the bright end. A profile whose dark end is above `threshold`
    (glare on the ink beside the part) or whose bright end is below it (a
    shadow, a speck on the part) has no trustworthy mid-level; a crossing more
    than `max_shift` px from where the binary edge is (half a pixel from the
    contour pixel towards the dark end) is the edge of something else.
    """
    a = 0.5 * (p[:, 0] + p[:, 1])
    b = 0.5 * (p[:, -1] + p[:, -2])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    where, dist = _nearest_crossing(p - (0.5 * (a + b))[:, None], s, np.sign(b - a)[:, None])
    ok = (dist <= max_shift) & (hi - lo >= min_contrast) & (lo < threshold) & (hi >= threshold)
    return where, ok


def _nearest_crossing(d, s, rising=None):
    """Offset along each profile where `d` changes sign nearest to the binary edge, and how
    far from it. The edge is half a pixel from the contour pixel towards the ink: the side
    `rising` (+1: the profile climbs to the part along s) says, or each crossing's own
    direction when None (a sliver's profile climbs and falls)."""
    d0, d1 = d[:, :-1], d[:, 1:]
    crosses = (d0 * d1 <= 0) & (d0 != d1)
    with np.errstate(divide="ignore", invalid="ignore"):
        where = s[:-1] + np.where(crosses, d0 / (d0 - d1), np.nan)
    rising = np.sign(d1 - d0) if rising is None else rising
    dist = np.where(crosses, np.abs(where + 0.5 * rising), np.inf)
    j = np.argmin(dist, axis=1)
    rows = np.arange(len(d))
    return where[rows, j], dist[rows, j]


def _points(c, n, t, ok):
    """The contour pixels' points moved `t` along their normals, where `ok`."""
    t = t[ok]
    return np.column_stack([c[ok, 0] + n[ok, 0] * t, c[ok, 1] + n[ok, 1] * t]).astype(np.float64)


def refine(
    img: np.ndarray,
    contour: np.ndarray,
    threshold: float,
    half: int = 4,
    min_contrast: float = 20.0,
    max_shift: float = 1.5,
):
    """Sub-pixel points (M, 2) (u, v) and the indices of the contour pixels they came from.

    Profiles are read from the 8-bit median-filtered main channel `img`.
    """
    c, n, s, x, y = _profiles(contour, half)
    p = sample_q8(img, x, y).astype(np.float32) * (1.0 / ONE)
    t, ok = _crossing(p, s, threshold, min_contrast, max_shift)
    return _points(c, n, t, ok), np.nonzero(ok)[0]


def refine_at(
    img: np.ndarray,
    contour: np.ndarray,
    subset: np.ndarray,
    level: float,
    half: int = 4,
    max_shift: float = 1.5,
):
    """Like `refine`, but where each profile passes `level` itself, not half-way between its ends.

    A top just out of the ink is a sliver a few pixels wide: a profile crosses it from ink to
    ink and never reaches the part's level, so it has no half-way point. Its edge is where it
    passes the threshold learned on it (above.py). Used only for the points `refine` dropped.
    """
    c, n, s, x, y = _profiles(contour, half, subset)
    p = sample_q8(img, x, y).astype(np.float32) * (1.0 / ONE)
    t, dist = _nearest_crossing(p - level, s)
    ok = dist <= max_shift
    return _points(c, n, t, ok), subset[ok]


def refine_colour(
    frame: np.ndarray,
    contour: np.ndarray,
    subset: np.ndarray,
    main: int,
    other: int,
    cut: float,
    half: int = 4,
    min_contrast: float = 20.0,
    max_shift: float = 1.5,
):
    """Like `refine`, on (main - other) of the raw colour frame: for the points glare took.

    Where a highlight on the ink beside the part is as bright as the part, the
    grey level has no edge left, but the colour has: lamp light added to blue
    ink stays blue. Used only for the few points `refine` dropped, so the
    cost stays with the frames that have glare.
    """
    c, n, s, x, y = _profiles(contour, half, subset)
    h, w = frame.shape[:2]
    flat = frame.reshape(-1)
    x = np.clip(x, 0, w - 1.001)
    y = np.clip(y, 0, h - 1.001)
    x0, y0 = x.astype(np.int32), y.astype(np.int32)
    fx, fy = x - x0, y - y0
    base = (y0 * w + x0) * 3

    def channel(k):
        i = base + k
        p00, p01 = flat.take(i).astype(np.float32), flat.take(i + 3).astype(np.float32)
        p10, p11 = flat.take(i + 3 * w).astype(np.float32), flat.take(i + 3 * w + 3).astype(np.float32)
        return (p00 * (1 - fx) + p01 * fx) * (1 - fy) + (p10 * (1 - fx) + p11 * fx) * fy

    p = channel(main) - channel(other)
    t, ok = _crossing(p, s, -cut, min_contrast, max_shift)
    return _points(c, n, t, ok), subset[ok]


def more_points(pts, idx, pixels, step, img, *args):
    """`pts`/`idx` (points of the contour `pixels` and the pixels they came from, as `refine`
    gives them) with the points `step(img, pixels, missing, *args)` places for the pixels
    they lack (`refine_colour`, `refine_at`), in contour order."""
    if len(idx) == len(pixels):
        return pts, idx
    more, midx = step(img, pixels, np.setdiff1d(np.arange(len(pixels)), idx), *args)
    if not len(midx):
        return pts, idx
    idx = np.concatenate([idx, midx])
    order = np.argsort(idx, kind="stable")
    return np.vstack([pts, more])[order], idx[order]


def bumps(pts: np.ndarray, k: int = 8, min_dev: float = 1.0, max_resid: float = 0.2) -> np.ndarray:
    """Mask of points on a short excursion from an otherwise smooth line (a speck stuck to it).

    A dust speck or bubble touching the waterline bends the binary contour round
    itself and the sub-pixel step follows the speck's edge. On either side of a
    bump the loop carries on along one smooth curve: a quadratic (in the frame
    of the chord from 2k points before to 2k points after) through the points
    k..2k before and after fits them to `max_resid` px while the point itself
    is more than `min_dev` px off it. At a corner of the part the quadratic
    cannot fit both legs, so corners are kept. On loops shorter than 16k points
    the window shrinks (a small loop curves too much over a wide one), down to
    k = 4; loops under 64 points are left alone.
    """
    n = len(pts)
    out = np.zeros(n, bool)
    k = min(k, n // 16)  # a small loop curves too much over a wide window
    if k < 4:
        return out
    # cheap screen: off the chord between the k-th neighbours (a smooth line of
    # radius > 4k px is within 0.5 px of it); only those get the quadratic test
    a, b = np.roll(pts, k, axis=0), np.roll(pts, -k, axis=0)
    c = b - a
    off = np.abs(c[:, 0] * (pts[:, 1] - a[:, 1]) - c[:, 1] * (pts[:, 0] - a[:, 0])) / (
        np.hypot(c[:, 0], c[:, 1]) + 1e-9
    )
    cand = np.nonzero(off > 0.5 * min_dev)[0]
    if len(cand) == 0:
        return out
    o = np.array([-2 * k, -(3 * k) // 2, -k, k, (3 * k) // 2, 2 * k])
    Y = pts[(cand[:, None] + o[None, :]) % n]  # (m, 6, 2)
    chord = Y[:, -1] - Y[:, 0]
    u = chord / (np.hypot(*chord.T)[:, None] + 1e-9)
    v = np.column_stack([-u[:, 1], u[:, 0]])
    rel = Y - Y[:, :1]
    x = np.einsum("njc,nc->nj", rel, u)
    y = np.einsum("njc,nc->nj", rel, v)
    A = np.stack([np.ones_like(x), x, x * x], axis=2)  # (n, 6, 3)
    M = np.einsum("nji,njk->nik", A, A) + 1e-6 * np.eye(3)
    coef = np.linalg.solve(M, np.einsum("nji,nj->ni", A, y)[..., None])[..., 0]
    resid = np.sqrt(np.mean((y - np.einsum("nji,ni->nj", A, coef)) ** 2, axis=1))
    p = pts[cand] - Y[:, 0]
    xi, yi = np.einsum("nc,nc->n", p, u), np.einsum("nc,nc->n", p, v)
    dev = np.abs(yi - (coef[:, 0] + coef[:, 1] * xi + coef[:, 2] * xi * xi))
    out[cand] = (dev > min_dev) & (resid < max_resid)
    return out
