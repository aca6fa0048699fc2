"""Cutters: the shape of the tool's lower end, as one radial profile.

Every cutter we support is a solid of revolution described by three numbers:
radius R, corner radius rc (0 <= rc <= R) and flute length (how deep below
the stock top it may reach before the shank or holder rubs):

    flat end   rc = 0        bull nose   0 < rc < R        ball end   rc = R

All the maths in this room (drop-cutter, the swept profile used to plan the
stepover, the milling simulation) only needs `profile(r)`: the height of the
cutter's lower surface above its tip at radial distance r from the axis.
For a bull nose the flat bottom has radius a = R - rc and the corner is a
torus of tube radius rc:

    h(r) = 0                                 r <= a
    h(r) = rc - sqrt(rc^2 - (r - a)^2)       a < r <= R

which is a ball for a = 0 and a flat end for rc = 0. h is convex and
increasing in r; the simulation relies on that (a convex sweep has a single
lowest point).

Named cutters (`--cutter ball6`, `flat3`, `bull6r1`) make the command line
short; the default finishing cutter is a 6 mm ball, the cutter most sculptured
surfaces are finished with.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import SettingError, check_mm

# Usable length below the holder. A 6 mm tool reaching 40 mm is a long-reach
# (necked) tool; the dissertation's samples stand up to ~37 mm above the base.
DEFAULT_FLUTE_FACTOR = 8.0


@dataclass(frozen=True)
class Cutter:
    diameter: float
    corner_radius: float
    flute_length: float
    flutes: int = 2

    def __post_init__(self):
        check_mm("cutter", self.diameter, what="diameter")
        if not (0 <= self.corner_radius <= self.radius + 1e-12):
            raise SettingError(
                "cutter",
                f"corner radius must be between 0 and the radius "
                f"{self.radius:g} mm, got {self.corner_radius}",
            )
        check_mm("cutter", self.flute_length, what="flute length")
        if int(self.flutes) < 1:
            raise SettingError("cutter", f"flutes must be >= 1, got {self.flutes}")

    @property
    def radius(self) -> float:
        return self.diameter / 2.0

    @property
    def kind(self) -> str:
        if self.corner_radius <= 1e-9:
            return "flat"
        if self.corner_radius >= self.radius - 1e-9:
            return "ball"
        return "bull"

    @property
    def name(self) -> str:
        d = f"{self.diameter:g}"
        if self.kind == "bull":
            return f"bull{d}r{self.corner_radius:g}"
        return f"{self.kind}{d}"

    def describe(self) -> str:
        return f"{self.kind} D{self.diameter:.3f} CR{self.corner_radius:.3f} FL{self.flute_length:.1f}"

    def profile(self, r):
        """Height of the lower surface above the tip at radial distance r (mm).

        Outside the cutter (r > R) the value is +inf: nothing of the cutter is there.
        """
        r = np.asarray(r, float)
        a = self.radius - self.corner_radius
        rc = self.corner_radius
        if rc > 0:
            # elementwise, no masks: the planner calls this on a million radii per pass
            t = np.clip(r - a, 0.0, rc)
            out = rc - np.sqrt(np.maximum(rc * rc - t * t, 0.0))
        else:
            out = np.zeros(r.shape)
        return np.where(r <= self.radius + 1e-12, out, np.inf)

    def offset(self, leave: float) -> Cutter:
        """The cutter grown by `leave` in every direction (for stock to leave).

        Its lower surface is the true cutter's, offset outward by `leave`, and
        its tip is `leave` below the true tip.
        """
        return Cutter(self.diameter + 2 * leave, self.corner_radius + leave, self.flute_length, self.flutes)


_NAME = re.compile(r"^(ball|flat|bull)(\d+(?:\.\d+)?)(?:r(\d+(?:\.\d+)?))?$")


def parse_cutter(text: str, flute_length: float | None = None, flutes: int = 2) -> Cutter:
    """`ball6`, `flat3`, `bull6r1` (diameter in mm, corner radius after r)."""
    m = _NAME.match(str(text).strip().lower())
    if not m:
        raise SettingError(
            "cutter",
            f"{text!r} is not a cutter name; use e.g. ball6, flat3 or bull6r1 "
            "(diameter in mm, bull corner radius after r)",
        )
    kind, d, rc = m.group(1), float(m.group(2)), m.group(3)
    if kind == "ball":
        if rc is not None:
            raise SettingError("cutter", f"{text!r}: a ball cutter has no separate corner radius")
        corner = d / 2
    elif kind == "flat":
        if rc is not None:
            raise SettingError("cutter", f"{text!r}: a flat cutter has no corner radius")
        corner = 0.0
    else:
        if rc is None:
            raise SettingError("cutter", f"{text!r}: a bull-nose cutter needs a corner radius, e.g. bull6r1")
        corner = float(rc)
        if corner <= 0 or corner >= d / 2:
            raise SettingError(
                "cutter",
                f"{text!r}: bull-nose corner radius must be between 0 and {d / 2:g} mm (exclusive)",
            )
    fl = DEFAULT_FLUTE_FACTOR * d if flute_length is None else float(flute_length)
    return Cutter(d, corner, fl, flutes)
