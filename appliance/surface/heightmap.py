"""The height map: the one surface type shared by surface, cam and outputs.

A regular lattice in the object frame (mm): `x` holds the column centres
(increasing), `y` the row centres (increasing, away from the viewer), and
`z[j, i]` is the height above the base top at (x[i], y[j]). NaN marks a cell
that is not on the part (off its footprint, or inside a hole down to the base).
Where the reconstruction knows it, each cell also carries its uncertainty in mm
(`sigma`) and how it was obtained (`source`, codes of uncertainty.SOURCES).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass
class HeightMap:
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    sigma: np.ndarray | None = None  # 1-sigma uncertainty per cell, mm, where known
    source: np.ndarray | None = None  # int8 per cell: index into uncertainty.SOURCES, -1 unknown

    def __post_init__(self):
        self.x = np.asarray(self.x, float)
        self.y = np.asarray(self.y, float)
        self.z = np.asarray(self.z, float)
        if self.z.shape != (self.y.size, self.x.size):
            raise ValueError(f"z has shape {self.z.shape}, expected {(self.y.size, self.x.size)}")
        for name in ("sigma", "source"):
            v = getattr(self, name)
            if v is not None and np.shape(v) != self.z.shape:
                raise ValueError(f"{name} has shape {np.shape(v)}, expected {self.z.shape}")

    @property
    def spacing(self):
        """(dx, dy) of the lattice; NaN for an axis with one sample."""
        dx = float(np.mean(np.diff(self.x))) if self.x.size > 1 else float("nan")
        dy = float(np.mean(np.diff(self.y))) if self.y.size > 1 else float("nan")
        return dx, dy

    @property
    def on_part(self):
        return np.isfinite(self.z)

    @property
    def outline(self):
        """The part's outermost cells: on it, with a side neighbour off it or off the lattice."""
        on = self.on_part
        return on & ~ndimage.binary_erosion(on, border_value=0)

    def grid(self):
        """X, Y arrays of the same shape as z."""
        return np.meshgrid(self.x, self.y)
