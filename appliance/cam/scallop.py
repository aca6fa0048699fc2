"""Scallops: what a stepover leaves between two neighbouring passes.

Formulas (docs/method.md). A ball of radius R stepping s over a flat leaves

    h = R - sqrt(R^2 - s^2 / 4)          and conversely    s = 2 sqrt(h (2R - h)),

and on a slope alpha *across* the passes the same h needs s = 2 cos(alpha)
sqrt(h (2R - h)). A bull nose behaves like a ball of radius rc plus its flat
bottom (s grows by 2 (R - rc)); a flat end leaves no scallop on a flat at all
but a saw-tooth on every slope, which is why it is a poor finishing cutter.

Those formulas assume a plane. Our planner does not: it measures the scallop
between two actual passes in the cross-section half-way between them, with
the *swept* cutter. A cutter moving along a path of slope t = tan(beta) cuts,
at lateral distance dy from its axis, down to

    tip + g(dy, t),   g(dy, t) = min over dx of  h(sqrt(dx^2 + dy^2)) - |t| dx

(the cutter a little further down the slope reaches lower than the one right
here). For a ball this is the swept cylinder, g = R - sqrt(R^2 - dy^2) sqrt(1 + t^2);
for a flat end g = -|t| sqrt(R^2 - dy^2). A bull nose is its flat disc of
radius a = R - rc (at height rc) grown by a ball of radius rc, so its sweep
is the union of the swept balls centred on that disc; the lowest of them at
lateral dy is centred on the disc's downhill rim at lateral v:

    g = min over v of  rc - |t| sqrt(a^2 - v^2) - sqrt(1 + t^2) sqrt(rc^2 - (dy - v)^2),

convex in v, so bisection on its derivative finds it (it was a golden
section over dx calling the profile forty times: 97 % of a bull-nose
program's time). Between
two passes the stock is min(tip_a + g(y - y_a), tip_b + g(y_b - y)), and the
scallop is that minus the design surface. Measured vertically, as the
verification measures it.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .cutters import Cutter


def ball_scallop(radius, stepover):
    """Scallop height of a ball of `radius` at `stepover` on a flat."""
    r, s = float(radius), float(stepover)
    return r - np.sqrt(max(r * r - s * s / 4.0, 0.0))


def ball_stepover(radius, scallop, slope_deg=0.0):
    """Stepover giving `scallop` for a ball on a flat, or on a slope across the passes."""
    r, h = float(radius), float(scallop)
    return 2.0 * np.cos(np.radians(slope_deg)) * np.sqrt(h * (2 * r - h))


def flat_stepover(cutter: Cutter, scallop):
    """The stepover the formulas give on a flat: the planner's first guess."""
    rc = cutter.corner_radius
    a = cutter.radius - rc
    if rc <= 0:
        return 0.9 * cutter.diameter
    return min(2 * a + ball_stepover(rc, min(scallop, rc)), 0.95 * cutter.diameter)


def swept_offset(cutter: Cutter, dy, slope):
    """g(dy, t): lowest point of the swept cutter above its tip, at lateral distance dy.

    +inf where |dy| > R (the cutter does not reach there).
    """
    dy = np.abs(np.asarray(dy, float))
    t = np.abs(np.asarray(slope, float))
    dy, t = np.broadcast_arrays(dy, t)
    R = cutter.radius
    c = np.sqrt(np.maximum(R * R - dy * dy, 0.0))
    reach = dy <= R + 1e-12
    kind = cutter.kind
    if kind == "ball":
        g = R - c * np.sqrt(1.0 + t * t)
    elif kind == "flat":
        g = -t * c
    else:
        g = _bull_swept(cutter, np.minimum(dy, R), t)
    return np.where(reach, g, np.inf)


_TABLE = 1025  # nodes per axis of the bull-nose table


def _bull_swept(cutter, dy, t):
    """g for a bull nose, read from a table of g cos(theta) over (psi, theta).

    dy = R sin(psi) and t = tan(theta) make the table smooth where g is not
    (g has a square-root edge at dy = R and grows without bound with t;
    g cos(theta) does neither: for a ball it is R cos(theta) - R cos(psi)).
    Bilinear reading errs by ~(pi / 2048)^2 / 8 x R, 3e-6 mm for R = 3,
    against the bisection's 10 ms per planner call (97 % of a bull-nose
    program's time before the table).
    """
    R = cutter.radius
    G = _bull_table(R, cutter.corner_radius)
    step = (np.pi / 2) / (_TABLE - 1)
    th = np.arctan(t)
    fi = np.arcsin(np.clip(dy / R, 0.0, 1.0)) / step
    fj = th / step
    i = np.minimum(fi.astype(int), _TABLE - 2)
    j = np.minimum(fj.astype(int), _TABLE - 2)
    u, w = fi - i, fj - j
    val = (
        (1 - u) * (1 - w) * G[i, j]
        + u * (1 - w) * G[i + 1, j]
        + (1 - u) * w * G[i, j + 1]
        + u * w * G[i + 1, j + 1]
    )
    return val / np.cos(th)


@lru_cache(maxsize=16)
def _bull_table(R, rc):
    ang = np.linspace(0.0, np.pi / 2, _TABLE)
    psi, th = np.meshgrid(ang, ang, indexing="ij")
    G = _bull_swept_exact(R, rc, R * np.sin(psi), np.cos(th), np.sin(th))
    G.flags.writeable = False
    return G


def _bull_swept_exact(R, rc, dy, cos_t, sin_t, iters=30):
    """g cos(theta) by bisection: the rim point v of the flat disc whose swept ball reaches lowest.

    The function of v, rc cos - sin sqrt(a^2 - v^2) - sqrt(rc^2 - (dy - v)^2),
    is convex, so its derivative's sign change brackets the minimum.
    """
    a = R - rc
    lo = np.maximum(-a, dy - rc)
    hi = np.full(dy.shape, a)
    for _ in range(iters):
        v = 0.5 * (lo + hi)
        w = dy - v
        up = sin_t * v * np.sqrt(np.maximum(rc * rc - w * w, 0.0)) > w * np.sqrt(
            np.maximum(a * a - v * v, 0.0)
        )
        hi = np.where(up, v, hi)
        lo = np.where(up, lo, v)
    v = 0.5 * (lo + hi)
    return (
        rc * cos_t
        - sin_t * np.sqrt(np.maximum(a * a - v * v, 0.0))
        - np.sqrt(np.maximum(rc * rc - (dy - v) ** 2, 0.0))
    )
