"""Spindle speed and feeds from the cutter and the material: a small table.

    rpm   = min(max_rpm, 1000 * Vc / (pi * D))
    feed  = rpm * flutes * fz,    fz = chip load per tooth (mm) = k * D
    plunge = plunge_factor * feed

Vc (surface speed, m/min), k (chip load per mm of diameter) and the plunge
factor are conservative figures for small carbide cutters on a light bench
mill (the kind the dissertation used: a Lab-Volt 5600), not a machinist's
handbook; they err on the slow side. `--feed`, `--plunge-feed` and
`--spindle` override any of them, and the machine's per-axis limits cap them
(limits.py).

| material  | Vc m/min | fz / D | plunge |
|-----------|----------|--------|--------|
| aluminium | 150      | 0.004  | 0.25   |
| wax       | 250      | 0.010  | 0.5    |
| wood      | 300      | 0.008  | 0.4    |
| foam      | 300      | 0.015  | 0.5    |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SettingError
from .cutters import Cutter

MATERIALS = {
    "aluminium": (150.0, 0.004, 0.25),
    "wax": (250.0, 0.010, 0.5),
    "wood": (300.0, 0.008, 0.4),
    "foam": (300.0, 0.015, 0.5),
}
DEFAULT_MATERIAL = "wax"
DEFAULT_MAX_RPM = 24000.0


@dataclass(frozen=True)
class Conditions:
    rpm: float
    feed: float  # mm/min, cutting
    plunge: float  # mm/min, downward into unknown stock


def conditions(
    cutter: Cutter,
    material: str = DEFAULT_MATERIAL,
    max_rpm: float = DEFAULT_MAX_RPM,
    feed: float | None = None,
    plunge: float | None = None,
    rpm: float | None = None,
) -> Conditions:
    if material not in MATERIALS:
        raise SettingError("material", f"unknown material {material!r}; known: {', '.join(MATERIALS)}")
    vc, k, pf = MATERIALS[material]
    if rpm is None:
        rpm = min(max_rpm, 1000.0 * vc / (np.pi * cutter.diameter))
    if feed is None:
        feed = rpm * cutter.flutes * k * cutter.diameter
    if plunge is None:
        plunge = pf * feed
    for name, v in (("spindle speed", rpm), ("feed", feed), ("plunge feed", plunge)):
        if not np.isfinite(v) or v <= 0:
            raise SettingError(name, f"must be > 0, got {v:g}")
    return Conditions(float(round(rpm)), float(round(feed)), float(round(plunge)))
