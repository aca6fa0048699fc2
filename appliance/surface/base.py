"""The base plane: what every height map must respect before it is milled.

The part stands on the base top, z = 0. Nothing of it is below that plane,
so a fitted height under zero is a fitting artefact (a smooth surface
overshooting at a rim, a level read a little low) and is clamped to the
plane. Cells with no height inside the part are either a real hole down to
the base (a ring's middle: wide, the base shows through) or a gap the
waterlines missed (narrow, beside a steep wall); the first are the base,
the second are filled from the cells around them.

None of this is fatal: a finishing program for every scan, with what was
done counted so the report can say it. Each changed cell says so in the
map's source (clamped, filled) and its uncertainty grows by what the change
reveals: a clamped cell was at least its dip off; a filled one is known no
better than the spread of the heights around it. `stand_on_base` is applied to the
height map `inkslice process` writes and to any map `inkslice toolpath`
reads, so both mill the same surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .heightmap import HeightMap

HOLE_TO_BASE_MM = 5.0  # a gap whose middle is this far from the part is a hole down to the base


@dataclass
class BaseFix:
    """What stand_on_base changed, for the report."""

    clamped_cells: int = 0  # cells that were below the base top
    deepest_dip_mm: float = 0.0  # how far below it the deepest was (>= 0)
    filled_cells: int = 0  # gap cells filled from their neighbours
    base_cells: int = 0  # hole cells set to the base top (a hole down to the base)

    @property
    def changed(self):
        return bool(self.clamped_cells or self.filled_cells or self.base_cells)

    def sentences(self) -> list[str]:
        out = []
        if self.clamped_cells:
            out.append(
                f"{self.clamped_cells} cells were below the base top (deepest "
                f"{self.deepest_dip_mm:.3f} mm) and were clamped to it"
            )
        if self.filled_cells:
            out.append(
                f"{self.filled_cells} cells with no height inside the part were filled from their neighbours"
            )
        if self.base_cells:
            out.append(f"{self.base_cells} cells of holes down to the base were set to the base top")
        return out

    def to_json(self):
        return {
            "clamped_cells": self.clamped_cells,
            "deepest_dip_mm": round(self.deepest_dip_mm, 4),
            "filled_cells": self.filled_cells,
            "base_cells": self.base_cells,
        }


def interior_holes(on_part):
    """Off-part cells not connected to the lattice border: gaps inside the part."""
    off = ~on_part
    lab, n = ndimage.label(off)
    if n == 0:
        return np.zeros_like(off)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    return off & ~np.isin(lab, border)


def stand_on_base(hm: HeightMap) -> tuple[HeightMap, BaseFix]:
    """hm with no height below the base top and no hole inside the part -> (map, what changed)."""
    z = hm.z.copy()
    fix = BaseFix()
    below = np.isfinite(z) & (z < 0.0)
    dip = np.where(below, -z, 0.0)
    if below.any():
        fix.clamped_cells = int(below.sum())
        fix.deepest_dip_mm = float(-z[below].min())
        z[below] = 0.0
    holes = interior_holes(np.isfinite(z))
    to_base = gaps = np.zeros_like(holes)
    if holes.any():
        dx, dy = hm.spacing
        depth = ndimage.distance_transform_edt(holes, sampling=(dy, dx))  # to the nearest part cell
        lab, n = ndimage.label(holes)
        widest = ndimage.maximum(depth, lab, np.arange(1, n + 1))
        to_base = np.isin(lab, 1 + np.flatnonzero(np.asarray(widest) >= HOLE_TO_BASE_MM))
        z[to_base] = 0.0
        fix.base_cells = int(to_base.sum())
        gaps = holes & ~to_base
        fix.filled_cells = int(gaps.sum())
        z = _fill_from_neighbours(z, gaps)
    if not fix.changed:
        return hm, fix
    sigma, source = _mark(hm, z, below, dip, gaps, to_base)
    return HeightMap(hm.x, hm.y, z, sigma, source), fix


def _mark(hm, z, clamped, dip, gaps, to_base):
    """The changed cells' source and uncertainty (see the module's docstring)."""
    from .uncertainty import CLAMPED, FILLED

    sigma = hm.sigma
    if sigma is not None:
        sigma = np.where(clamped, np.hypot(np.nan_to_num(sigma), dip), sigma)
        if gaps.any():
            ring = ndimage.binary_dilation(gaps, np.ones((3, 3))) & ~gaps & np.isfinite(hm.z)
            around = z[ring]
            spread = float(np.ptp(around)) if around.size else 0.0
            worst = float(np.nanmax(sigma[ring])) if ring.any() and np.isfinite(sigma[ring]).any() else 0.0
            sigma = np.where(gaps, np.hypot(worst, spread / 2), sigma)
        sigma = np.where(to_base, 0.0, sigma)  # the base top itself is exact
    source = hm.source  # a map that never said stays silent
    if source is not None:
        source = source.copy()
        source[clamped | to_base] = CLAMPED
        source[gaps] = FILLED
    return sigma, source


def _fill_from_neighbours(z, gaps):
    """Fill `gaps` inward, ring by ring, each cell the mean of its known 8 neighbours,
    then relax the filled cells a little so the rings do not show as terraces."""
    z = z.copy()
    todo = gaps.copy()
    kernel = np.ones((3, 3))
    while todo.any():
        known = np.isfinite(z) & ~todo
        total = ndimage.convolve(np.where(known, z, 0.0), kernel, mode="constant")
        count = ndimage.convolve(known.astype(float), kernel, mode="constant")
        ring = todo & (count > 0)
        if not ring.any():
            break
        z[ring] = total[ring] / count[ring]
        todo &= ~ring
    for _ in range(20):
        known = np.isfinite(z)
        total = ndimage.convolve(np.where(known, z, 0.0), kernel, mode="constant")
        count = ndimage.convolve(known.astype(float), kernel, mode="constant")
        z[gaps] = total[gaps] / np.maximum(count[gaps], 1)
    return z
