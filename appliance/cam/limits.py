"""Machine limits: the travel envelope and the per-axis feed limits.

A program that would leave the envelope is refused, naming the axis, the
first offending move and how far out it goes: clipping it silently would mill
a different part (or drive into a hard stop).

Feeds are different: a controller never exceeds an axis' maximum anyway; it
slows the whole move down. We do the same, explicitly and in the program
(segment by segment F = min(F, max_a * L / |d_a|)), so the run-time estimate
is honest and no controller has to guess.

Coordinates are the program's (work) coordinates: program Z = object z + work
offset. The default envelope is a small bench mill with the work zero at the
base's front-left corner: X -10..310, Y -10..210, Z -5..150 mm; X/Y move at
up to 3000 mm/min, Z at 1000 mm/min, rapids at 3000 mm/min.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SettingError
from .program import FEED, Program


@dataclass(frozen=True)
class Machine:
    travel: tuple = ((-10.0, 310.0), (-10.0, 210.0), (-5.0, 150.0))
    max_feed: tuple = (3000.0, 3000.0, 1000.0)
    rapid: float = 3000.0

    def __post_init__(self):
        for ax, (lo, hi) in zip("XYZ", self.travel):
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise SettingError("machine travel", f"{ax} range {lo:g}..{hi:g} is empty or not finite")
        for ax, f in zip("XYZ", self.max_feed):
            if not np.isfinite(f) or f <= 0:
                raise SettingError("machine max feed", f"{ax} must be > 0 mm/min, got {f:g}")
        if not np.isfinite(self.rapid) or self.rapid <= 0:
            raise SettingError("machine rapid", f"must be > 0 mm/min, got {self.rapid:g}")


# the machine every program is checked against unless one is given (frozen: shared safely)
DEFAULT_MACHINE = Machine()


def _numbers(text, count: int, setting: str, form: str) -> list[float]:
    """`count` comma-separated numbers, else a SettingError that shows the form wanted."""
    try:
        v = [float(s) for s in str(text).split(",")]
    except ValueError:
        v = []
    if len(v) != count:
        raise SettingError(setting, f"{text!r}: give {form}")
    return v


def parse_travel(text) -> tuple:
    """'xmin,xmax,ymin,ymax,zmin,zmax' (mm)."""
    v = _numbers(text, 6, "machine travel", "six numbers xmin,xmax,ymin,ymax,zmin,zmax (mm)")
    return ((v[0], v[1]), (v[2], v[3]), (v[4], v[5]))


def parse_feeds(text) -> tuple:
    """'fx,fy,fz' (mm/min)."""
    return tuple(_numbers(text, 3, "machine max feed", "three numbers fx,fy,fz (mm/min)"))


def check_envelope(prog: Program, machine: Machine):
    for ax, name in enumerate("XYZ"):
        lo, hi = machine.travel[ax]
        v = prog.xyz[:, ax]
        bad = np.flatnonzero((v < lo - 1e-9) | (v > hi + 1e-9))
        if bad.size:
            k = int(bad[0])
            over = max(lo - v[bad].min(), v[bad].max() - hi)
            raise SettingError(
                "machine travel",
                f"the program leaves the {name} travel {lo:g}..{hi:g} mm by {over:.3f} mm "
                f"({bad.size} moves, first: move {k + 1} to {name}{v[k]:.3f}); "
                "move the work offset or use a machine with more travel",
            )


def limit_feeds(prog: Program, machine: Machine, start=None) -> int:
    """Cap each feed move's F by the axis limits; returns how many moves were slowed."""
    p = prog.xyz.copy()
    p[0, :2] = p[0, :2] if start is None else np.asarray(start, float)[:2]
    d = np.abs(np.diff(np.vstack([p[:1], p]), axis=0))
    L = np.linalg.norm(d, axis=1)
    mf = np.asarray(machine.max_feed, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        cap = np.min(np.where(d > 1e-12, mf[None, :] * L[:, None] / d, np.inf), axis=1)
    feed = prog.kind == FEED
    slow = feed & (cap < prog.feed - 1e-9)
    # 1 % below the cap and rounded down to whole mm/min, so the printed F still
    # respects it after the coordinates are rounded to the dialect's decimals
    prog.feed = np.where(slow, np.floor(0.99 * cap), prog.feed)
    return int(slow.sum())
