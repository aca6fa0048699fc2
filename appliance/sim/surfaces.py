"""Known parts for the virtual bench.

Each part is a block standing on the base: vertical walls up from the base
top (z = 0) along a footprint, and a sculptured top z = top(x, y). The
dissertation's four samples (closed forms recovered from its appendices, docs/method.md)
are here, lifted by `diss_offset` so they stand on the base, plus parts of our
own that exercise what the samples do not: islands that merge, a ring with a
hole, steep walls, a flat plateau, and two reference shapes for calibration.

Two queries matter:
- `height(x, y)`: the part's height above the base top (0 off the part);
- `level_sdf(x, y, level)`: signed distance in mm, in the base plane, to the
  waterline at `level` (positive where the part stands above the liquid). The
  renderer uses it to anti-alias the waterline exactly; tests use it as the
  analytic level curve.

Stepped parts are unions of tiers; a tier is a footprint with its own top.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

# -- footprints: signed distance, positive inside ----------------------------


def rect_sdf(x0, x1, y0, y1):
    cx, cy, hx, hy = (x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2, (y1 - y0) / 2

    def sdf(x, y):
        qx, qy = np.abs(x - cx) - hx, np.abs(y - cy) - hy
        outside = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0))
        inside = np.minimum(np.maximum(qx, qy), 0)
        return -(outside + inside)

    return sdf


def disc_sdf(cx, cy, r):
    return lambda x, y: r - np.hypot(x - cx, y - cy)


def ring_sdf(cx, cy, r_in, r_out):
    def sdf(x, y):
        r = np.hypot(x - cx, y - cy)
        return np.minimum(r_out - r, r - r_in)

    return sdf


@dataclass(frozen=True)
class Tier:
    footprint: Callable  # sdf(x, y), mm, > 0 inside
    top: Callable  # z(x, y), mm above the base top


@dataclass(frozen=True)
class Surface:
    name: str
    description: str
    bounds: tuple  # (xmin, xmax, ymin, ymax) of the footprint, mm
    tiers: tuple
    diss_offset: float = 0.0  # z_dissertation = z - diss_offset (samples only)
    table_normaliser: float | None = None  # max |Z| the dissertation's tables divided by
    tags: tuple = field(default_factory=tuple)

    def height(self, x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        z = np.zeros(np.broadcast(x, y).shape)
        for t in self.tiers:
            z = np.where(t.footprint(x, y) >= 0, np.maximum(z, t.top(x, y)), z)
        return z

    def inside(self, x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        return np.any([t.footprint(x, y) >= 0 for t in self.tiers], axis=0)

    def level_sdf(self, x, y, level, eps=1e-4):
        """Signed distance (mm) to the waterline at `level`, > 0 above the liquid.

        Exact for the walls; first order for the sculptured top: (top - level)
        / |grad top|, which is exact to well under a micrometre within the
        pixel-wide band where the renderer uses it.
        """
        x, y = np.asarray(x, float), np.asarray(y, float)
        best = np.full(np.broadcast(x, y).shape, -np.inf)
        for t in self.tiers:
            z = t.top(x, y)
            gx = (t.top(x + eps, y) - t.top(x - eps, y)) / (2 * eps)
            gy = (t.top(x, y + eps) - t.top(x, y - eps)) / (2 * eps)
            g = np.hypot(gx, gy)
            with np.errstate(divide="ignore", invalid="ignore"):
                d_top = np.where(g > 1e-9, (z - level) / g, np.where(z >= level, np.inf, -np.inf))
            best = np.maximum(best, np.minimum(t.footprint(x, y), d_top))
        return best

    @property
    def z_max(self):
        X, Y = self.sample_grid(401)
        return float(np.max(self.height(X, Y)))

    @property
    def z_min_top(self):
        """Lowest point of the sculptured top: below it a scan sees only walls."""
        X, Y = self.sample_grid(401)
        inside = self.inside(X, Y)
        return float(np.min(self.height(X, Y)[inside]))

    def sample_grid(self, n=50):
        xmin, xmax, ymin, ymax = self.bounds
        return np.meshgrid(np.linspace(xmin, xmax, n), np.linspace(ymin, ymax, n))

    def to_dissertation(self, z):
        return np.asarray(z) - self.diss_offset


# -- the dissertation's samples (appendices B-E, docs/method.md) ------------------


def _sample1(x, y):
    return -33.3363 + 33.3175 * np.exp(-((x - 50.001) ** 2 + (y - 50.001) ** 2) / 1389.99)


def _saddle(size, base):
    def f(x, y):
        u, v = x / size, y / size
        return base + 45 * (u * v**3 - u**3 * v)

    return f


_BEZ = np.array([[45, 47, 50, 40], [21, 25, 37, 50], [62, 53, 46, 36], [46, 25, 22, 43]], float)


def _bezier_t(s):
    """Invert x = 75 t + 25 t^3 (monotone) by Newton; s in [0, 100]."""
    s = np.asarray(s, float)
    t = s / 100.0
    for _ in range(30):
        t = t - (75 * t + 25 * t**3 - s) / (75 + 75 * t**2)
    return t


def _bernstein(t):
    return np.stack([(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t**2 * (1 - t), t**3])


def _sample3(x, y):
    # Clamp so the top extends smoothly (flat in t) just outside the patch: the
    # renderer and the sdf's finite differences look a hair past the footprint.
    bu = _bernstein(_bezier_t(np.clip(x, 0, 100)))
    bv = _bernstein(_bezier_t(np.clip(y, 0, 100)))
    return np.einsum("i...,ij,j...->...", bu, _BEZ, bv)


def _lifted(f, offset):
    return lambda x, y: f(x, y) + offset


def _dissertation_sample(name, desc, size, f, offset, normaliser, at=0.0):
    """A sample lifted by `offset` onto the base, its corner at (at, at) on the base: the
    100 mm samples fill the base, the 10 mm one stands at its centre, under the camera,
    where anybody would put a small part (at the base's corner it stood 60 mm off the
    camera's axis, and its 40 mm-tall rims hid most of its own waterlines)."""
    top = _lifted(lambda x, y: f(x - at, y - at), offset)
    return Surface(
        name,
        desc,
        (at, at + size, at, at + size),
        (Tier(rect_sdf(at, at + size, at, at + size), top),),
        diss_offset=offset,
        table_normaliser=normaliser,
        tags=("dissertation",),
    )


# Offsets lift each sample so its lowest top point is ~5 mm above the base.
SAMPLE1 = _dissertation_sample(
    "sample1", "Gaussian dome, 100 x 100 mm (dissertation sample 1)", 100.002, _sample1, 37.42, 32.42
)
SAMPLE2 = _dissertation_sample(
    "sample2",
    "four-fold saddle, 100 x 100 mm (dissertation sample 2)",
    100.0,
    _saddle(100.0, -17.31),
    39.63,
    34.62,
)
SAMPLE3 = _dissertation_sample(
    "sample3", "bicubic Bezier patch, 100 x 100 mm (dissertation sample 3)", 100.0, _sample3, 0.0, 49.81
)
SAMPLE4 = _dissertation_sample(
    "sample4",
    "steep saddle, 10 x 10 mm (dissertation sample 4)",
    10.0,
    _saddle(10.0, 2.25),
    20.07,
    28.36,
    at=45.0,
)


# -- our own parts -------------------------------------------------------------


def _gauss(cx, cy, s, a):
    return lambda x, y: a * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))


def _twin_peaks_top(x, y):
    return 6 + _gauss(30, 40, 12, 24)(x, y) + _gauss(62, 40, 10, 18)(x, y)


TWIN_PEAKS = Surface(
    "twin-peaks",
    "two hills on a 90 x 80 mm block: two islands that merge as the level drops",
    (0.0, 90.0, 0.0, 80.0),
    (Tier(rect_sdf(0, 90, 0, 80), _twin_peaks_top),),
)


def _ring_top(x, y):
    r = np.hypot(x - 50, y - 50)
    return 8 + 12 * np.cos((r - 30) / 15 * (np.pi / 2)) ** 2


RING = Surface(
    "ring",
    "a rounded ring, outer radius 45 mm, hole of radius 15 mm down to the base",
    (5.0, 95.0, 5.0, 95.0),
    (Tier(ring_sdf(50, 50, 15, 45), _ring_top),),
)


def _crater_top(x, y):
    # a ridge cresting at 22 mm on radius 20 mm, falling to a bowl 5.1 mm deep in the middle
    # and to 5 mm at the disc's edge
    r = np.hypot(x - 50, y - 50)
    return 5 + 17 * np.exp(-(((r - 20) / 9) ** 2))


CRATER = Surface(
    "crater",
    "a ring-shaped ridge round a crater with a floor, on a disc of radius 42 mm: contact "
    "lines that bend round the ink inside and round the part outside",
    (8.0, 92.0, 8.0, 92.0),
    (Tier(disc_sdf(50, 50, 42), _crater_top),),
)


def _steep_front_top(x, y):
    # a body rising gently from the back (x = 90) to its brow at x ~ 55, then dropping 20 mm
    # in ~10 mm (slopes to 2, 63 deg) to a 4 mm apron; rounded off sideways
    front = 1.0 / (1.0 + np.exp(-(x - 52) / 2.5))
    side = np.exp(-(((y - 40) / 24) ** 2))
    return 4 + 20 * front * side * (0.55 + 0.45 * np.clip((90 - x) / 38, 0, 1))


STEEP_FRONT = Surface(
    "steep-front",
    "a body with a steep front: a rounded hump whose face drops 20 mm at up to "
    "63 deg to a 4 mm apron, on a 90 x 80 mm block",
    (0.0, 90.0, 0.0, 80.0),
    (Tier(rect_sdf(0, 90, 0, 80), _steep_front_top),),
)


def _flat(h):
    return lambda x, y: np.full(np.broadcast(np.asarray(x), np.asarray(y)).shape, float(h))


def _tilted(h, ax, ay):
    return lambda x, y: h + ax * (x - 50) + ay * (y - 40)


STEPS = Surface(
    "steps",
    "a block with a boss and a pocket rim: vertical walls inside the top",
    (0.0, 100.0, 0.0, 80.0),
    (
        Tier(rect_sdf(0, 100, 0, 80), _tilted(8, 0.05, 0.03)),
        Tier(rect_sdf(20, 60, 15, 55), _tilted(22, 0.04, -0.02)),
        Tier(disc_sdf(75, 45, 12), lambda x, y: 30 - 0.02 * ((x - 75) ** 2 + (y - 45) ** 2)),
    ),
)


def _mesa_top(x, y):
    # flat at 25 mm inside r < 22, a smooth shoulder down to 10 mm by r = 38
    r = np.hypot(x - 50, y - 45)
    s = np.clip((r - 22) / 16, 0, 1)
    return 25 - 15 * (3 * s**2 - 2 * s**3)


PLATEAU = Surface(
    "plateau",
    "a mesa: flat top at 25 mm, smooth shoulders, on a 100 x 90 mm block",
    (0.0, 100.0, 0.0, 90.0),
    (Tier(rect_sdf(0, 100, 0, 90), _mesa_top),),
)


def _sphere_top(cx, cy, r, z0):
    def f(x, y):
        d2 = (x - cx) ** 2 + (y - cy) ** 2
        return z0 + np.sqrt(np.maximum(r * r - d2, 0.0))

    return f


SPHERE = Surface(
    "sphere",
    "reference: a 30 mm-radius cap on a disc of radius 29 mm (meniscus calibration)",
    (21.0, 79.0, 21.0, 79.0),
    (Tier(disc_sdf(50, 50, 29), _sphere_top(50, 50, 30, 0.0)),),
    tags=("reference",),
)

CONE = Surface(
    "cone",
    "reference: a 30-degree cone of base radius 35 mm on a 3 mm disc (meniscus calibration)",
    (15.0, 85.0, 15.0, 85.0),
    (Tier(disc_sdf(50, 50, 35), lambda x, y: 3 + np.tan(np.radians(30)) * (35 - np.hypot(x - 50, y - 50))),),
    tags=("reference",),
)


# -- parts whose steep faces hide their own waterlines from the camera ------------------


def _soft_min(a, b, r):
    """min(a, b) with the crease rounded over ~r mm of height: a rim the camera sees as a
    smooth silhouette, as a machined edge with a small radius would be."""
    return np.minimum(a, b) - r * np.log1p(np.exp(-np.abs(a - b) / r))


def _battered(footprint, top, angle_deg, foot_mm=0.2, r=0.3):
    """A tier whose walls lean in at `angle_deg` from the base (a batter): the top
    `top(x, y)`, cut by a face rising from `foot_mm` at the footprint's edge."""
    rise = np.tan(np.radians(angle_deg))
    return lambda x, y: _soft_min(top(x, y), foot_mm + rise * footprint(x, y), r)


_STEP_LOW = rect_sdf(8, 92, 10, 86)
_STEP_HIGH = rect_sdf(44, 87, 20, 64)

STEPPED_BLOCK = Surface(
    "stepped-block",
    "a stepped block with 85 deg outer walls: a 12 mm tier and on it a nearly flat "
    "plateau at ~30 mm, set off the camera's axis so that the walls facing away from it are hidden "
    "by their own rims",
    (8.0, 92.0, 10.0, 86.0),
    (
        Tier(_STEP_LOW, _battered(_STEP_LOW, _tilted(12, 0.01, 0.005), 85.0)),
        Tier(_STEP_HIGH, _battered(_STEP_HIGH, _tilted(30, 0.015, -0.01), 85.0)),
    ),
    tags=("occluding",),
)


def _blade_top(x, y):
    # a blade along y on a 3.6 mm slab: its crest sweeps from x = 70 to 86 and rises along the
    # span, its gentle flank steepens (a twist), its other flank falls at 84 deg towards +x,
    # away from the camera; the ends taper over 10 mm
    t = np.clip((y - 50) / 35, -1, 1)
    xc = 78 + 8 * t
    u = x - xc
    h = 20 + 3 * t
    gentle = h + (0.45 - 0.15 * t) * u
    steep = h - np.tan(np.radians(84.0)) * u
    ends = np.clip(np.minimum(y - 12, 88 - y) / 10, 0, 1)
    ends = ends * ends * (3 - 2 * ends)
    return 3.6 + ends * np.maximum(_soft_min(gentle, steep, 0.3), 0.0)


BLADE = Surface(
    "blade",
    "a twisted blade on a 3.6 mm slab: a swept crest 17-23 mm high, one gentle flank and one "
    "at 84 deg facing away from the camera, which its crest hides",
    (10.0, 95.0, 8.0, 92.0),
    (Tier(rect_sdf(10, 95, 8, 92), _blade_top),),
    tags=("occluding",),
)


SURFACES = {
    s.name: s
    for s in (
        SAMPLE1,
        SAMPLE2,
        SAMPLE3,
        SAMPLE4,
        TWIN_PEAKS,
        RING,
        CRATER,
        STEEP_FRONT,
        STEPS,
        PLATEAU,
        STEPPED_BLOCK,
        BLADE,
        SPHERE,
        CONE,
    )
}
DISSERTATION_SAMPLES = ("sample1", "sample2", "sample3", "sample4")


def get(name) -> Surface:
    try:
        return SURFACES[name]
    except KeyError:
        from ..errors import SettingError

        raise SettingError("surface", f"unknown surface {name!r}; known: {', '.join(SURFACES)}") from None


# -- what commissioning puts on the base (sim/staging.py) --------------------------

BASE_PLATE = Surface(
    "base plate",
    "the empty base: its flat top at level zero, 120 x 120 mm",
    (-10.0, 110.0, -10.0, 110.0),
    (Tier(rect_sdf(-10, 110, -10, 110), _flat(0.0)),),
)

_BALLS: dict = {}


def ball(diameter_mm=25.4, cx=50.0, cy=50.0) -> Surface:
    """A precision ball lying on the base, seen from above: its upper hemisphere on its
    equator's outline (appliance.surface.reference.Ball has the same shape)."""
    key = (round(float(diameter_mm), 4), round(float(cx), 4), round(float(cy), 4))
    if key not in _BALLS:
        d, x, y = key
        r = d / 2
        _BALLS[key] = Surface(
            f"ball {d:g} mm",
            f"reference: a {d:g} mm precision ball lying on the base",
            (x - r, x + r, y - r, y + r),
            (Tier(disc_sdf(x, y, r), _sphere_top(x, y, r, r)),),
            tags=("reference",),
        )
    return _BALLS[key]
