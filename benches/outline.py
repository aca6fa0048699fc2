"""Where a height map disagrees with the part's outline, which a mean over the part never shows.

Ea, p99 and max are taken over the grid nodes inside the true outline. Two mistakes fall
outside them and both reach the machinist:
- material the map puts where the part is not (a tab beside a wall, a bright blob left as a
  spike): the finishing program leaves it standing, and no error over the part counts it;
- the part beyond the map's grid: no node there, so no error either, and the program mills
  it away.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

ON_BASE_MM = 0.1  # a node this near the base plane is the base: a pocket's floor, no material


def spurious(surface, hm) -> tuple[float, float]:
    """-> (mm², tallest mm): the map's nodes standing above the base more than one node from
    the true outline (the nodes next to it straddle the edge, so are not counted), and the
    highest of them."""
    X, Y = hm.grid()
    near = ndimage.binary_dilation(surface.inside(X, Y), np.ones((3, 3)))
    with np.errstate(invalid="ignore"):
        extra = (hm.z > ON_BASE_MM) & ~near
    cell = abs(hm.x[1] - hm.x[0]) * abs(hm.y[1] - hm.y[0])
    return float(extra.sum() * cell), float(hm.z[extra].max()) if extra.any() else 0.0


def outside_map(surface, hm, cell_mm=0.05) -> float:
    """mm² of the part beyond the map's grid."""
    xmin, xmax, ymin, ymax = surface.bounds
    x = np.arange(xmin - 1.0, xmax + 1.0, cell_mm)
    y = np.arange(ymin - 1.0, ymax + 1.0, cell_mm)
    X, Y = np.meshgrid(x, y)
    beyond = (X < hm.x[0]) | (X > hm.x[-1]) | (Y < hm.y[0]) | (Y > hm.y[-1])
    return float((surface.inside(X, Y) & beyond).sum() * cell_mm**2)
