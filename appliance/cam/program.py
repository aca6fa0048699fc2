"""A machining program as moves, before any dialect: the motion hygiene.

Runs of tool-tip positions (object frame: z up from the base top) become
moves that are safe on a real mill the first time:

* The program starts with the tool going straight up to the safe height
  (stock top + clearance) before any horizontal move: wherever the tool was
  left, nothing is above the stock.
* Rapids (G0) happen only at the safe height, or straight up out of a cut
  (the column above the cutter is the cutter's own, so it is empty).
* Every descent into possible material is a G1 at the plunge feed, from the
  safe height down to the first point of a run; cutting moves use the
  cutting feed.
* The spindle starts before the first descent and stops after the final
  retract; the program ends with M30.

Program Z = object z + `z_offset` (the work offset: where the base top is in
the work coordinate system); every header states it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SettingError, check_mm
from .cutters import Cutter
from .feeds import Conditions

RAPID, FEED = 0, 1
DEFAULT_CLEARANCE = 5.0  # mm above the stock top


@dataclass
class Program:
    kind: np.ndarray  # (n,) RAPID or FEED
    xyz: np.ndarray  # (n, 3) end point of each move, program frame
    feed: np.ndarray  # (n,) mm/min (NaN for rapids)
    rpm: float
    cutter: Cutter
    title: str
    z_offset: float
    safe_z: float  # program frame
    notes: list = field(default_factory=list)

    def runtime(self, rapid_rate: float, start=None) -> float:
        """Estimated seconds: path length / feed, rapids at `rapid_rate`; no acceleration."""
        p = np.vstack([self.xyz[:1] if start is None else np.asarray(start, float)[None], self.xyz])
        L = np.linalg.norm(np.diff(p, axis=0), axis=1)
        rate = np.where(self.kind == RAPID, rapid_rate, self.feed)
        return float(np.sum(L / rate) * 60.0)


def check_frame(clearance, z_offset):
    """Refuse a safe height or work offset no program can be written with.

    The jobs call it before planning (a finishing plan takes seconds to
    minutes, and then failed on its last step); a NaN work offset was written
    out as `G0 Znan` and the command reported success.
    """
    check_mm("clearance", clearance)
    if not np.isfinite(z_offset):
        raise SettingError("z offset", f"must be a number of mm, got {z_offset}")


def build_program(
    runs,
    cutter: Cutter,
    cond: Conditions,
    stock_top: float,
    title: str,
    clearance: float = DEFAULT_CLEARANCE,
    z_offset: float = 0.0,
) -> Program:
    check_frame(clearance, z_offset)
    runs = [np.asarray(r, float) for r in runs if len(r)]
    if not runs:
        raise SettingError("toolpath", "has no cutting moves (is the part outside the margin?)")
    top = max(float(stock_top), max(float(r[:, 2].max()) for r in runs))
    safe = top + clearance
    kinds, pts, feeds = [], [], []

    def add(k, p, f=np.nan):
        kinds.append(k)
        pts.append(p)
        feeds.append(f)

    first = runs[0][0]
    add(RAPID, (np.nan, np.nan, safe))  # straight up, XY unchanged
    for r in runs:
        add(RAPID, (r[0, 0], r[0, 1], safe))
        add(FEED, tuple(r[0]), cond.plunge)
        for p in r[1:]:
            add(FEED, tuple(p), cond.feed)
        add(RAPID, (r[-1, 0], r[-1, 1], safe))
    xyz = np.array(pts, float)
    xyz[:, 2] += z_offset
    # the first move keeps the controller's XY: fill with the first run's XY for bookkeeping
    xyz[0, :2] = first[:2]
    prog = Program(
        np.array(kinds),
        xyz,
        np.array(feeds, float),
        cond.rpm,
        cutter,
        title,
        float(z_offset),
        safe + z_offset,
    )
    return prog
