"""The seed's G-code: the dissertation's own format (appendix A), kept for comparison.

"Seed" is the project's word for the dissertation's baseline (its vision
method is vision/seed.py, its surface surface/seed.py). Users choose this
format as the `dissertation` dialect, the name they know it by.

Every grid point becomes a G01 move in a zig-zag that holds X and sweeps Y,
alternating direction; absolute millimetres, spindle 1500 rpm, feed 1500,
N-numbered lines, M30 at the end. Z is measured down from the stock top
(the part's highest point), so every cut is at Z <= 0.

There is no cutter compensation: surface points are used as tool-tip
positions, so any real cutter gouges concave regions. appliance.cam's
finishing programs exist to fix that; this one is here so the difference can
be measured (inkslice verify).
"""

from __future__ import annotations

import numpy as np

from ..surface.heightmap import HeightMap


def seed_gcode(hm: HeightMap, stock_top: float | None = None, spindle: int = 1500, feed: int = 1500) -> str:
    top = float(np.nanmax(hm.z)) if stock_top is None else float(stock_top)
    lines = ["G90 G21", f"M03 S{spindle}"]
    first = True
    for i, x in enumerate(hm.x):
        rows = range(len(hm.y)) if i % 2 == 0 else range(len(hm.y) - 1, -1, -1)
        for j in rows:
            z = hm.z[j, i]
            if not np.isfinite(z):
                continue
            move = f"X{x:.2f} Y{hm.y[j]:.4f} Z{z - top:.4f}"
            lines.append(f"G01 {move} F{feed}" if first else move)
            first = False
    lines.append("M30")
    return "".join(f"N{k:05d} {line}\n" for k, line in enumerate(lines, start=1))
