"""Scallops: what a stepover leaves between two neighbouring passes.

Formulas (toolchain notes). A ball of radius R stepping s over a flat leaves

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
for a flat end g = -|t| sqrt(R^2 - dy^2); for a bull nose g is found by a
golden-section search (the function of dx is convex because h is). Between
two passes the stock is min(tip_a + g(y - y_a), tip_b + g(y_b - y)), and the
scallop is that minus the design surface. Measured vertically, as the
verification measures it.
"""
from __future__ import annotations

import numpy as np

from .cutters import Cutter
from .segments import golden_section



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
        g = _golden_min(cutter, dy, t, c)
    return np.where(reach, g, np.inf)


def _golden_min(cutter, dy, t, c, iters=40):
    f = lambda dx: cutter.profile(np.minimum(np.hypot(dx, dy), cutter.radius)) - t * dx
    _, f1, _, f2, _, _ = golden_section(f, np.zeros(dy.shape), c.copy(), iters)
    ends = np.minimum(f(np.zeros(dy.shape)), f(c))
    return np.minimum(np.minimum(f1, f2), ends)
