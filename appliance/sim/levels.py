"""Which levels a simulated scan of a known part visits."""

from __future__ import annotations

import math

from .physics import meniscus_rise


def sculpture_levels(surface, step, below_mm=0.0, from_above=False, above_mm=0.0):
    """The dissertation's practice: one picture per step from the first in which the top
    shows, down to the first in which the whole sculptured top stands above the ink.

    Above the top a frame shows only ink (and glare, which the baseline's Otsu
    threshold would take for the part); below the top's lowest point it shows
    only the block's walls again. With a meniscus the ink clings to the top until
    it is the rise below it: `below_mm` more (the rise on a wall, ~3.8 mm for
    water) keeps the scan going until the whole top is really out.

    `from_above` starts as the daemon does instead: from the first level above the top,
    a frame that shows no part (the daemon descends from the first level that shows none).
    A top that lies on a level then has a frame above it that bounds it. An ink that does
    not wet flat faces leaves a top while it still stands up to `above_mm` over it: the
    daemon's first empty frame is that much higher.
    """
    from .scanrender import scan_levels

    lowest = surface.z_min_top - step - below_mm
    highest = float("inf") if from_above else surface.z_max
    levels = scan_levels(surface, step, above_mm if from_above else 0.0)
    return [lv for lv in levels if lowest <= lv < highest]


def ink_margins(effects) -> tuple[float, float]:
    """-> (below_mm, above_mm) for sculpture_levels under `effects` (an Effects): how far below
    the top's lowest point the ink still clings to it (the rise on a wall), and how far over a
    flat top it has left an ink that does not wet flat faces still stands (the depression, a
    pit's contact line up to sqrt(2) times more: physics.curvature_factor). Both 0 with no
    meniscus."""
    if not effects.meniscus:
        return 0.0, 0.0
    l_c, theta = effects.capillary_length_mm, math.radians(effects.contact_angle_deg)
    below = float(meniscus_rise(math.pi / 2, l_c, theta))
    above = -math.sqrt(2) * float(meniscus_rise(0.0, l_c, theta))
    return max(below, 0.0), max(above, 0.0)
