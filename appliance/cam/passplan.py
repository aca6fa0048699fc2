"""Stepover planning: the passes placed one by one, each as far as the scallop allows.

For a candidate next pass the planner drops the cutter along it and measures
the scallop it leaves against the passes placed (cusps.py). It searches
(secant on s^2, bracketed) for the largest stepover whose scallop is within
90-98 % of the request: the flat-surface formula (scallop.py) is only the
first guess, it errs by 10-15 % on slopes across the passes and on curved
surfaces.
"""

from __future__ import annotations

import numpy as np

from .cusps import PassProbe
from .scallop import ball_stepover, flat_stepover


def plan_passes(sampler, st, e1, e2, t0, n, s0, s1, meet=None, opening=None):
    """(across positions from s0 to s1, both included; the tips of each pass).

    `meet`: a planner working towards this one from the far end (bands.py): its
    `end(sa, s1, measured, step_max)`, asked before each pass with the candidates measured so
    far, is where this one is to stop now."""
    h = st.scallop
    lo_ok, hi_ok, aim = 0.90 * h, 0.98 * h, 0.95 * h
    probe = PassProbe(sampler, st, e1, e2, t0, n, opening=opening)
    # never more than 1.5 x the flat-surface stepover: convex surfaces allow a
    # little more, but a cross-section where nothing could be measured (the
    # pass along an uphill edge touching only the edge) must not open a gap
    s_cap = min(0.95 * st.cutter.diameter, 1.5 * flat_stepover(st.cutter, h))
    # a flat bottom on a slope m leaves a staircase of risers m x s whatever its
    # diameter, so the floor is 2 % of the ball-like stepover, not of the flat one
    # (0.108 mm for a 6 mm flat end held 0.06 where 0.05 was asked on a 0.4 slope)
    s_min = max(
        0.02 * min(flat_stepover(st.cutter, h), ball_stepover(st.cutter.radius, h)), st.resolution / 10
    )
    guess = flat_stepover(st.cutter, h)
    done = [probe.pass_at(s0)]
    measured = 0  # candidates measured: the planner's clock (bands.py)
    passes = [s0]
    while True:
        sa = passes[-1]
        if meet is not None:
            s1 = meet.end(sa, s1, measured, 1.01 * s_cap)
        if sa >= s1 - 1e-9:
            break
        best_ok, best_p, best_sc, worst = None, None, 0.0, np.inf
        s = min(guess, s_cap, s1 - sa)
        tried = []
        for _ in range(10):
            cand = probe.pass_at(sa + s)
            sc = probe.scallop(done, cand)
            measured += 1
            tried.append((s, sc))
            if sc <= hi_ok:
                if best_ok is None or s > best_ok:
                    best_ok, best_p, best_sc = s, cand, sc
                    probe.keep_only(cand[0])
                if sc >= lo_ok or sa + s >= s1 - 1e-9 or s >= s_cap - 1e-9:
                    break
            else:
                worst = min(worst, s)
            nxt = _secant(tried, aim)
            lo_b = best_ok if best_ok is not None else s_min
            nxt = min(nxt, s_cap, s1 - sa, worst)
            if not (lo_b < nxt < worst) or abs(nxt - s) < 1e-4:
                nxt = 0.5 * (lo_b + min(worst, s_cap, s1 - sa))
            if abs(nxt - s) < 1e-5:
                break
            s = nxt
        if best_ok is None:
            best_ok = s_min
            best_p = probe.pass_at(sa + s_min)
        nxt = min(sa + best_ok, s1)
        if s1 - nxt < s_min:
            # a last sliver narrower than the smallest step: end on the boundary
            # instead of adding a pass a fraction of a micron from it
            nxt = s1
            best_p = probe.pass_at(s1)
        passes.append(nxt)
        done.append(best_p if best_p[0] == nxt else probe.pass_at(nxt))
        # the next pass starts from this step, re-aimed: a step accepted at 90 % of the
        # request is tried a little wider, one at 98 % a little narrower
        guess = best_ok * float(np.clip(np.sqrt(aim / best_sc), 0.9, 1.1)) if best_sc > 1e-12 else best_ok
    return np.array(passes), np.stack([p[1] for p in done])


def _secant(tried, aim):
    """The next step to try from the (step, scallop) pairs tried so far for this pass.

    The scallop grows as s^2 on a plane, but not on a wall along the passes or where an
    earlier pass's cusp is what holds it (on the daemon's sphere it grew as s^0.6 there,
    and steps of s^2's secant crept up to the window over eight candidates): with two
    pairs the exponent is the one they show, kept within [0.5, 4]."""
    s, sc = tried[-1]
    if sc <= 1e-12:
        return 2 * s
    p = 2.0
    if len(tried) >= 2:
        s_b, sc_b = tried[-2]
        usable = 1e-12 < min(sc, sc_b) and max(sc, sc_b) < np.inf
        if usable and abs(np.log(s / s_b)) > 1e-3 and abs(np.log(sc / sc_b)) > 1e-6:
            p = float(np.clip(np.log(sc / sc_b) / np.log(s / s_b), 0.5, 4.0))
    return s * (aim / sc) ** (1.0 / p)
