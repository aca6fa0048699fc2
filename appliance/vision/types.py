"""What vision hands to surface: the waterline of one frame, in mm.

Loops are closed polylines in the object frame (x right, y away from the
viewer, mm on the liquid plane); the first point is not repeated at the end.
Orientation carries topology: an outer boundary of a part island runs
counter-clockwise (positive signed area), a hole's boundary clockwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Waterline:
    level_mm: float
    loops: list = field(default_factory=list)  # list of (N, 2) float64 arrays, mm

    @property
    def points(self) -> np.ndarray:
        """All loop points stacked, (M, 2)."""
        if not self.loops:
            return np.zeros((0, 2))
        return np.vstack(self.loops)


def signed_area(loop: np.ndarray) -> float:
    x, y = loop[:, 0], loop[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
