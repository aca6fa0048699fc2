"""A cutter against a straight segment, in closed form: shared by the edge
contacts of the drop-cutter and the sweep of the milling simulation.

For a segment c(t) = A + t w (t in [0, 1]) and a point q in the plane,

    m(q) = min over t of  c_z(t) + h(|q - c_xy(t)|)

over the t where q is within the cutter's radius of c_xy(t) (an interval,
from a quadratic). Two uses:

* simulation: c is the tool tip moving along a G1 and m(q) is the lowest the
  swept cutter reaches above q;
* drop-cutter against an edge of the part: with c_z negated, -m(q) is
  max over t of z_edge(t) - h(|q - e(t)|), the tip height at which a cutter
  above q touches the edge segment. The lattice cannot give that exactly
  because an edge is a cliff: a point just past it reads the base.

The function of t is convex (h convex and increasing, |q - c_xy(t)| convex,
c_z linear), so its minimum over the interval is exact: in closed form for a
ball (the stationary point of c_z(t) + R - sqrt(R^2 - rho(t)^2), clamped),
at an end of the interval for a flat end (h = 0 inside), and by a
golden-section search (20 steps, 7e-5 of the interval; the function is flat at
its minimum, so the error in height is second order) for a bull nose.
"""

from __future__ import annotations

import numpy as np

from .cutters import Cutter

_GOLD = (np.sqrt(5.0) - 1.0) / 2.0


def min_over_segment(cutter: Cutter, dx, dy, wx, wy, wz, az):
    """m(q) for q - A = (dx, dy) and w = B - A; +inf where q is never under the cutter."""
    R = cutter.radius
    args = [np.asarray(v, float) for v in (dx, dy, wx, wy, wz, az)]
    shape = np.broadcast_shapes(*(v.shape for v in args))
    # flat from here on: the bull nose's search picks elements by flat index. A direction
    # given once for every element (a cell's side, the move between two positions of a
    # pass) stays a scalar: spread over the elements it was a quarter of the call
    dx, dy, wx, wy, wz, az = (
        v if k in (2, 3) and v.ndim == 0 else np.broadcast_to(v, shape).ravel() for k, v in enumerate(args)
    )
    W2 = wx * wx + wy * wy
    still = W2 < 1e-18
    moving = not np.any(still)  # every segment has an xy extent: the guards below are no-ops
    Ws = W2 if moving else np.where(still, 1.0, W2)
    tm = (dx * wx + dy * wy) / Ws
    tm = tm if moving else np.where(still, 0.0, tm)
    dperp2 = np.maximum(dx * dx + dy * dy - tm * tm * W2, 0.0)
    ok = dperp2 <= R * R + 1e-9  # rounding must not drop a cell at exactly the rim
    delta = np.sqrt(np.maximum(R * R - dperp2, 0.0) / Ws)
    delta = delta if moving else np.where(still, np.inf, delta)
    lo = np.maximum(tm - delta, 0.0)
    hi = np.minimum(tm + delta, 1.0)
    ok &= lo <= hi + 1e-9
    hi = np.maximum(hi, lo)
    kind = cutter.kind
    if kind == "ball":
        A2 = np.maximum(R * R - dperp2, 0.0)
        u = -wz * np.sqrt(A2) / np.sqrt(Ws * (Ws + wz * wz))
        t = np.clip(tm + u, lo, hi)
    elif kind == "flat":
        t = np.where(wz >= 0, lo, hi)
    else:
        t = _golden(cutter, az, wz, np.broadcast_to(W2, tm.shape), tm, dperp2, lo, hi)
    if not moving:  # a segment with no xy extent: the lower end counts
        t = np.where(still, np.where(wz >= 0, 0.0, 1.0), t)
    rho2 = np.minimum(dperp2 + W2 * (t - tm) ** 2, R * R)
    if kind == "ball":
        prof = R - np.sqrt(R * R - rho2)
    elif kind == "flat":
        prof = 0.0
    else:
        prof = cutter.profile(np.sqrt(rho2))
    val = az + wz * t + prof
    return np.where(ok, val, np.inf).reshape(shape)


def golden_section(f, lo, hi, iters):
    """Golden-section search for the minimum of f on [lo, hi], element by element.

    Returns the final bracket: its two inner points with their values, and its ends.
    """
    x1 = hi - _GOLD * (hi - lo)
    x2 = lo + _GOLD * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(iters):
        left = f1 <= f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        x2n = np.where(left, x1, lo + _GOLD * (hi - lo))
        x1n = np.where(left, hi - _GOLD * (hi - lo), x2)
        f1n = np.where(left, f(x1n), f2)
        f2 = np.where(left, f1, f(x2n))
        f1 = f1n
        x1, x2 = x1n, x2n
    return x1, f1, x2, f2, lo, hi


def _golden(cutter, az, wz, W2, tm, dperp2, lo, hi, iters=20):
    """t of the bull nose's minimum on [lo, hi].

    The function is convex, so its slope at the two ends (closed form) settles
    most pairs at once: at lo if it already rises there, at hi if it still
    falls. Only the rest, where h' balances the segment's slope somewhere
    inside, are searched (golden section): that was every pair before, the
    whole cost of verifying a bull-nose program.
    """
    R, rc = cutter.radius, cutter.corner_radius
    a = R - rc
    lo = np.array(lo, float, copy=True)
    hi = np.maximum(np.array(hi, float, copy=True), lo)

    def slope(t):
        r = np.sqrt(np.minimum(dperp2 + W2 * (t - tm) ** 2, R * R))
        e = np.clip(r - a, 0.0, rc)
        dh = np.where(r > a, e / np.sqrt(np.maximum(rc * rc - e * e, 1e-300)), 0.0)
        return wz + dh * W2 * (t - tm) / np.where(r > 0, r, 1.0)

    s_lo, s_hi = slope(lo), slope(hi)
    t = np.where(s_lo >= 0, lo, hi)
    k = np.flatnonzero((s_lo < 0) & (s_hi > 0))
    if k.size:
        azk, wzk, W2k, tmk, dpk = az[k], wz[k], W2[k], tm[k], dperp2[k]
        f = lambda u: azk + wzk * u + cutter.profile(np.sqrt(np.minimum(dpk + W2k * (u - tmk) ** 2, R * R)))
        x1, f1, x2, f2, _, _ = golden_section(f, lo[k], hi[k], iters)
        best = np.where(f1 <= f2, x1, x2)
        # the ends of the whole interval too (a flat bottom makes the minimum sit there);
        # not the narrowed bracket's ends, which golden_section also returns
        e0, e1, fb = f(lo[k]), f(hi[k]), f(best)
        t[k] = np.where(e0 <= np.minimum(e1, fb), lo[k], np.where(e1 <= fb, hi[k], best))
    return t
