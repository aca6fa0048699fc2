"""Z-level (waterline) roughing: take a raw block down to the part plus stock to leave.

Levels go down from the stock top by the step-down. At each level the cutter
moves in a zig-zag over the block at

    z = max(level, tip_leave(x, y))

where tip_leave is the drop-cutter height of the cutter grown by `leave`
(so it stays `leave` off the part in every direction, not just vertically),
and only where that removes something: where z is below what the previous
level left. Each stretch that cuts is one run (the program builder plunges
into it from the safe height and retracts after it), so the cutter never
rubs along material it is not meant to cut and never descends more than one
step-down into new stock. The last level follows tip_leave everywhere: the
block is left an even `leave` above the part for the finishing pass.

Roughing does not need finishing accuracy: it samples the surface every
`resolution` along a row (0.25 mm by default) with the cutter's offset
lattice at the same spacing; the drop-cutter's error there (~0.01 mm) is far
inside the stock to leave (0.3 mm by default).

A flat end mill of 6 mm is the default roughing cutter; the step-over is 40 %
of its diameter and the step-down 1 mm (wax, wood; use less in aluminium).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SettingError, check_mm
from .cutters import Cutter
from .polyline import reduce_polyline, true_runs
from .sampling import Sampler
from .zigzag import check_fits

DEFAULT_STEPDOWN = 1.0
DEFAULT_LEAVE = 0.3
DEFAULT_STEPOVER_FRACTION = 0.4


@dataclass
class RoughSettings:
    cutter: Cutter
    stock_top: float
    stepdown: float = DEFAULT_STEPDOWN
    leave: float = DEFAULT_LEAVE
    stepover: float | None = None
    resolution: float = 0.25
    chord: float = 0.01

    def check(self):
        check_mm("step-down", self.stepdown)
        if self.stepdown > self.cutter.flute_length:
            raise SettingError(
                "step-down",
                f"{self.stepdown:g} mm is deeper than the flute length {self.cutter.flute_length:g} mm",
            )
        so = self.stepover_mm
        check_mm("stepover", so)
        if so >= self.cutter.diameter:
            raise SettingError(
                "stepover",
                f"{so:g} mm is not less than the cutter diameter "
                f"{self.cutter.diameter:g} mm: ridges would be left standing",
            )
        check_mm("stock to leave", self.leave, zero_ok=True)
        check_mm("resolution", self.resolution)

    @property
    def stepover_mm(self):
        return DEFAULT_STEPOVER_FRACTION * self.cutter.diameter if self.stepover is None else self.stepover


def roughing(sampler: Sampler, st: RoughSettings):
    """Runs (lists of (k, 3) tip positions), in cutting order, level by level."""
    st.check()
    check_fits(sampler, st.cutter)
    x0, x1, y0, y1 = sampler.bounds
    d = min(st.resolution, st.cutter.radius / 3)
    nx = int(np.ceil((x1 - x0) / d - 1e-9)) + 1
    k = int(np.ceil((y1 - y0) / st.stepover_mm - 1e-9))
    ys = np.linspace(y0, y1, k + 1)
    xs = x0 + d * np.arange(nx)
    grown = st.cutter.offset(st.leave) if st.leave > 0 else st.cutter
    origins = np.column_stack([np.full(ys.size, x0), ys])
    from .dropcutter import drop_lines

    tip = drop_lines(sampler, grown, origins, (1.0, 0.0), nx, d) + st.leave
    top = float(st.stock_top)
    if top < float(tip.max()) - 1e-9:
        raise SettingError(
            "stock top", f"{top:.3f} mm is below the part plus stock to leave ({tip.max():.3f} mm)"
        )
    depth = top - float(tip.min())
    if depth > st.cutter.flute_length:
        raise SettingError(
            "cutter",
            f"flute length {st.cutter.flute_length:g} mm is shorter than the "
            f"depth to rough ({depth:.1f} mm from the stock top)",
        )
    left = np.full(tip.shape, top)  # what the previous level left under each point
    runs = []
    level = top
    while True:
        level = level - st.stepdown
        z = np.maximum(level, tip)
        cut = z < left - 1e-6
        if cut.any():
            for j in range(ys.size):
                row = []
                for a, b in true_runs(cut[j]):
                    pts = np.column_stack([xs[a:b], np.full(b - a, ys[j]), z[j, a:b]])
                    row.append(reduce_polyline(pts, st.chord))
                if j % 2 == 1:
                    row = [r[::-1] for r in row[::-1]]
                runs.extend(row)
            left = np.minimum(left, z)
        if level <= tip.min():
            break
    return runs
