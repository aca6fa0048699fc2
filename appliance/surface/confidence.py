"""Where a height map is unsure, told to the machinist: the G-code header and the report.

Cells whose uncertainty exceeds a threshold (uncertainty.DEFAULT_UNCERTAIN_MM) are grouped
into connected regions, boxed in millimetres, largest first. The part's outermost cells are
told apart, as one region of their own listed after the rest (Region.edge): where a wall
meets the base the map knows the outline only to a cell, and a node there may stand
anywhere from the base to the wall's height (surface/edges.py). Joined to the regions
inside, they made one region of the whole part: sample 3, scanned to 24 mm as the
dissertation did, was "X -0.3..100.1 Y -0.2..100.1 mm, 40.2 % of the part, up to 13.53
mm", the 13.53 being its edge nodes' height spread.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .uncertainty import DEFAULT_UNCERTAIN_MM, SOURCES


@dataclass
class Region:
    xmin: float
    xmax: float
    ymin: float
    ymax: float
    cells: int
    share: float  # of the part's cells
    worst_mm: float
    source: str  # the commonest source in it
    z_mm: float  # its median height
    edge: bool = False  # the part's outermost cells, all round

    def describe(self):
        if self.edge:
            return (
                f"the part's edge, {self.cells} cells round its outline ({100 * self.share:.1f} % of "
                f"the part), up to {self.worst_mm:.2f} mm: the outline is known to a cell there, "
                "and the program keeps the top edge over the cells on a wall"
            )
        return (
            f"X {self.xmin:.1f}..{self.xmax:.1f} Y {self.ymin:.1f}..{self.ymax:.1f} mm, "
            f"{100 * self.share:.1f} % of the part, up to {self.worst_mm:.2f} mm, mostly {self.source}"
        )


def low_confidence_regions(hm, threshold_mm=DEFAULT_UNCERTAIN_MM):
    """Connected regions of cells whose uncertainty exceeds the threshold, largest first
    (8-connected; the bounding boxes are of cell centres +- half a cell), and the part's
    outermost such cells as one last region (Region.edge). [] when the map carries no
    uncertainty."""
    if hm.sigma is None:
        return []
    unsure = hm.on_part & np.isfinite(hm.sigma) & (hm.sigma > threshold_mm)
    rim = hm.outline  # the cells the CAM keeps at the edge where they are walls (cam/sampling.py)
    edge = unsure & rim
    inside = regions(hm, unsure & ~rim)
    if not edge.any():
        return inside
    whole = ndimage.find_objects(edge.astype(int))[0]
    return inside + [_region(hm, whole, edge, int(hm.on_part.sum()), edge=True)]


def regions(hm, mask):
    """The connected regions of `mask` on hm's cells (8-connected), largest first."""
    if not mask.any() or not hm.on_part.any():
        return []
    lab, _ = ndimage.label(mask, structure=np.ones((3, 3)))
    total = int(hm.on_part.sum())
    out = [_region(hm, sl, lab == k, total) for k, sl in enumerate(ndimage.find_objects(lab), start=1)]
    out.sort(key=lambda r: -r.cells)
    return out


def _region(hm, sl, mask, total: int, edge=False) -> Region:
    """The region of `mask`'s cells within the slices `sl` of hm's grid (`total`: the
    part's cells)."""
    dx, dy = hm.spacing
    dx = dx if np.isfinite(dx) else 0.0
    dy = dy if np.isfinite(dy) else 0.0
    m = mask[sl]
    src = None if hm.source is None else hm.source[sl][m]
    common = "unknown"
    if src is not None and (src >= 0).any():
        common = SOURCES[int(np.bincount(src[src >= 0].astype(int)).argmax())]
    return Region(
        float(max(hm.x[sl[1].start] - dx / 2, hm.x[0])),
        float(min(hm.x[sl[1].stop - 1] + dx / 2, hm.x[-1])),
        float(max(hm.y[sl[0].start] - dy / 2, hm.y[0])),
        float(min(hm.y[sl[0].stop - 1] + dy / 2, hm.y[-1])),
        int(m.sum()),
        float(m.sum()) / total,
        float(np.max(hm.sigma[sl][m])) if hm.sigma is not None else float("nan"),
        common,
        float(np.median(hm.z[sl][m])),
        edge,
    )


def header_notes(hm, threshold_mm=DEFAULT_UNCERTAIN_MM, most=8):
    """G-code comment lines naming the low-confidence regions (nothing without an uncertainty)."""
    if hm.sigma is None:
        return []
    found = low_confidence_regions(hm, threshold_mm)
    if not found:
        return [f"confidence: every cell of the height map within {threshold_mm:g} mm"]
    inside = [r for r in found if not r.edge]
    at_edge = " and at its edge" if len(inside) < len(found) else ""
    lines = [
        f"low confidence: {100 * sum(r.share for r in found):.1f} % of the part in {len(inside)} "
        f"region(s){at_edge} with uncertainty over {threshold_mm:g} mm; check these after milling"
    ]
    for i, r in enumerate(inside[:most], start=1):
        lines.append(f"low confidence {i}: {r.describe()}")
    if len(inside) > most:
        rest = inside[most:]
        lines.append(
            f"low confidence: {len(rest)} smaller region(s), {100 * sum(r.share for r in rest):.1f} % "
            "of the part"
        )
    lines += [f"low confidence: {r.describe()}" for r in found if r.edge]
    return lines


def source_summary(hm):
    """{source: share of the part's cells} for the report."""
    if hm.source is None:
        return {}
    on = hm.on_part & (hm.source >= 0)
    total = int(hm.on_part.sum())
    return {
        name: float(np.sum(on & (hm.source == k))) / total
        for k, name in enumerate(SOURCES)
        if total and np.any(on & (hm.source == k))
    }
