"""Which levels a simulated scan of a known part visits."""
from __future__ import annotations


def sculpture_levels(surface, step):
    """The dissertation's practice: one picture per step from the first in which the top
    shows, down to the first in which the whole sculptured top stands above the ink.

    Above the top a frame shows only ink (and glare, which the baseline's Otsu
    threshold would take for the part); below the top's lowest point it shows
    only the block's walls again.
    """
    from .scanrender import scan_levels
    return [lv for lv in scan_levels(surface, step) if surface.z_min_top - step <= lv < surface.z_max]
