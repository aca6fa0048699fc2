"""The stepover planner on several cores: the part cut into bands across the passes.

Placing passes is sequential (each candidate is measured against the passes before it), and
it is most of a finishing program's time: on the daemon's demo scan 7 of 8.5 s. But a pass
placed exactly on a band's boundary ends the band below it (the planner lands its last pass
on the far bound) and starts the band above it (the first pass sits on the near bound): the
same pass twice, dropped once. So each band is planned on its own, in a forked worker, and
the passes are the bands' passes end to end. Every band keeps the scallop within the
request on its own; a band's first passes are measured without the cuts of the band below,
which only lowers the real stock between them. What it costs is a pass or two per boundary.

The bands split the part's footprint into equal areas, which is what the planner's work
follows. Each band's probe opens the design over its own rows and a cutter's reach beyond
(envelope.py; the opening was a quarter of the planning), on the whole part's lattice, so
the values are the same (to the float32 rounding of the erosion's reference height).
Forked workers share the map without copying; each returns its passes and tips through a
pipe. Where the bands may fork is forks.py's business (the processing child and the
commands; never the daemon with its threads); elsewhere it plans in one band.
"""

from __future__ import annotations

import numpy as np

from .forks import in_workers, workers
from .passplan import plan_passes

MIN_BAND_MM = 20.0  # narrower bands are not worth a fork and the extra boundary passes


def band_bounds(sampler, e2, s0: float, s1: float, bands: int) -> list[float]:
    """Boundaries s0 < b1 < ... < s1 that split the footprint's cells into `bands` equal shares
    along e2 (fewer where a band would be narrower than MIN_BAND_MM)."""
    bands = max(1, min(bands, int((s1 - s0) // MIN_BAND_MM)))
    if bands == 1:
        return [s0, s1]
    jj, ii = np.nonzero(sampler.cell_on)
    s = (sampler.x0 + sampler.dx * (ii + 0.5)) * e2[0] + (sampler.y0 + sampler.dy * (jj + 0.5)) * e2[1]
    cuts = np.quantile(s, np.arange(1, bands) / bands) if s.size else np.linspace(s0, s1, bands + 1)[1:-1]
    inner = [float(c) for c in cuts if s0 + MIN_BAND_MM / 2 < c < s1 - MIN_BAND_MM / 2]
    return [s0, *sorted(inner), s1]


def plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1):
    """plan_passes over [s0, s1], in bands on forked workers where allowed."""
    bounds = band_bounds(sampler, e2, s0, s1, workers())
    tasks = [
        (lambda a=a, b=b: plan_passes(sampler, st, e1, e2, t0, n, a, b))
        for a, b in zip(bounds[:-1], bounds[1:])
    ]
    if len(tasks) == 1:
        return tasks[0]()
    planned = in_workers(tasks)
    passes = [planned[0][0]] + [p[1:] for p, _ in planned[1:]]
    tips = [planned[0][1]] + [t[1:] for _, t in planned[1:]]
    return np.concatenate(passes), np.concatenate(tips)
