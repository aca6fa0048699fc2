"""A frame that showed nothing bounds the summit beneath it.

A scan that starts above the part has frames in which no waterline shows. At the lowest of
them, level L_e, no contact line touched the part anywhere: the apparent surface (top minus
the meniscus' rise) stood below L_e everywhere. Where the top is level, the rise is h(0):
zero for an ink that wets (a depression, below zero, for one that does not). So a top that
is round at its summit stands at most L_e + max(h(0), 0) there, whatever the fit says.

The fit does not know it. The top is solved from the apparent surface with a smooth rise
(contact_lines.py), and the rise the flanks need (1-2 mm on the ring's and the plateau's
shoulders, harsh bench) is carried over a round crest or onto a flat top: the ring's crest
came out 1.2 mm high, a tent with its apex where the truth is round, the plateau's 25 mm
top 0.5-1.7 mm high next to its rim. The solve holds the top under the ceiling at every
step (contact_lines.top_from_apparent), so the crest's flanks settle under it too.

A knife-edge rim is the exception: on slopes near a wall the ink climbs h(90 deg) and keeps
a rim under frames well below its top (sample 4's summit rim, 38.9 mm, first showed at
36 mm), and a top that is not round at its summit is not level anywhere near it. The first
frame that shows the part tells them apart: the band of top it shows is about
step / slope wide on each side (step: the level gap to the empty frame above it), a few
tenths of a millimetre on sample 4's rims (slopes 4-10), a millimetre or more on the
ring's round crest. The bound holds when that band's half-width (its area over its
perimeter) is at least step / SUMMIT_SLOPE; then on the whole part. Its blind spots: a
knife-edge rim on a part whose highest summit is round, and a summit too small to survive
the vision's dust filter at L_e (it would be cut to L_e).
"""

from __future__ import annotations

import numpy as np

SUMMIT_SLOPE = 2.0  # steeper (63 deg) at its first waterline, a summit is taken for a rim


def band_half_width(sl) -> float:
    """Half the width of the band a slice encloses: its area over its perimeter (a disc of
    radius R: R / 2; a thin band: half its width)."""
    perimeter = sl.length()
    return abs(sl.area()) / perimeter if perimeter > 0 else 0.0


def summit_ceiling(slices, model=None) -> float:
    """-> the highest the top can stand (inf when nothing bounds it): the level of the lowest
    frame above the part that showed nothing, plus the rise on a level face, when the first
    frame that shows the part shows a round summit."""
    top = next((k for k, s in enumerate(slices) if not s.empty), None)
    if top is None or top == 0:
        return np.inf  # no frame above the part: nothing bounds its summit
    step = slices[top - 1].level - slices[top].level
    if band_half_width(slices[top]) < step / SUMMIT_SLOPE:
        return np.inf  # a knife-edge rim: the ink keeps it under frames below its top
    level_rise = max(float(model.rise(0.0)), 0.0) if model is not None else 0.0
    return slices[top - 1].level + level_rise
