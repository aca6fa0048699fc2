"""Steep and shallow finishing: constant-Z (waterline) passes on steep walls,
zig-zag on the rest, and the same within a region (rest machining).

Why: a zig-zag pass climbing a wall parallel to it steps over sideways, and a
sideways step on a wall of slope theta leaves a vertical cusp 1 / cos(theta)
times the one it leaves on a flat; holding the scallop there takes passes a
few hundredths of a millimetre apart over the whole part. A waterline pass
runs around the wall at one height; consecutive levels dz apart are dz /
sin(theta) apart along the wall, so the wall is finished with a few dozen
loops.

The regions come from the tool-tip field T (the drop-cutter height of every
axis position on a lattice `grid` apart, 0.2 mm): its slope is the slope of
the surface where the cutter touches. Steep is T's slope >= threshold
(default 50 degrees, the `steep_angle_deg` setting); the two regions overlap
by `overlap_deg` either side of it and by a band `blend` mm wide (half the
cutter's radius; the zig-zag's band stops 15 degrees past its limit, it does
not climb the walls), so every position belongs to one of them and the seam is
cut by both: no gap, and no gouge, because every tool position of either is a
drop-cutter height (the cutter touches the design and cannot cut into it).

Waterlines: contours of T at levels dz apart (marching squares on the
lattice), kept where they lie in the steep region, resampled every
`resolution`, each point moved across its contour onto its level by exact
drops, the lowest level just above the floor so a wall is cut to its foot
(levels.py: how far apart, and why on the level), then refined where the
straight moves between points would cut in (zigzag.refine) and thinned to
the chord tolerance.

Zig-zag on the shallow region: passes a fixed stepover apart, the stepover
that holds the scallop on a slope of threshold + overlap across the passes
(scallop.py); finer than the planner's on a flat, but with no planning cost.

Rest machining: after a larger tool, a smaller one cuts only where the
larger's opening (opening.py: what it could reach at all) stands more than
`rest_tol` above the design, grown by the small cutter's radius so it rides
in from cut surface; inside that region, steep and shallow as above.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ..errors import SettingError, check_mm
from .contact import drop_lines, drop_points
from .contours import contours
from .cutters import Cutter
from .levels import FOOT, level_step, on_level, steepest
from .polyline import reduce_polyline, refine, refine_tolerance, true_runs
from .scallop import ball_stepover, flat_stepover
from .zigzag import check_fits, pass_frame

DEFAULT_STEEP_DEG = 50.0
DEFAULT_OVERLAP_DEG = 5.0
SEAM_DEG = 15.0  # how far past its limit the zig-zag's overlap band may climb


@dataclass
class SteepSettings:
    cutter: Cutter
    scallop: float = 0.05
    threshold_deg: float = DEFAULT_STEEP_DEG
    overlap_deg: float = DEFAULT_OVERLAP_DEG
    resolution: float = 0.1
    grid: float = 0.2
    angle: float = 0.0
    chord: float | None = None
    blend: float | None = None

    def __post_init__(self):
        if self.chord is None:
            self.chord = (
                min(0.002, self.scallop / 20) if np.isfinite(self.scallop) and self.scallop > 0 else 0.002
            )
        if self.blend is None:
            self.blend = self.cutter.radius / 2

    def check(self):
        R = self.cutter.radius
        if not (np.isfinite(self.scallop) and 0 < self.scallop < R):
            raise SettingError(
                "scallop", f"must be > 0 mm and less than the cutter radius {R:g} mm, got {self.scallop}"
            )
        if not (np.isfinite(self.threshold_deg) and 5 <= self.threshold_deg <= 85):
            raise SettingError(
                "steep_angle_deg", f"must be between 5 and 85 degrees, got {self.threshold_deg}"
            )
        if not (
            np.isfinite(self.overlap_deg)
            and 0 <= self.overlap_deg < min(self.threshold_deg, 90 - self.threshold_deg)
        ):
            raise SettingError(
                "steep overlap", f"must be >= 0 and leave both regions, got {self.overlap_deg}"
            )
        check_mm("resolution", self.resolution)
        check_mm("grid", self.grid)
        check_mm("chord tolerance", self.chord)
        if self.resolution > R / 3:
            raise SettingError(
                "resolution", f"{self.resolution:g} mm is too coarse for a cutter of radius {R:g} mm"
            )


@dataclass
class TipField:
    xs: np.ndarray
    ys: np.ndarray
    tip: np.ndarray  # (ny, nx) drop-cutter heights; NaN where the axis is off the part
    slope_deg: np.ndarray  # (ny, nx)

    @property
    def g(self):
        return float(self.xs[1] - self.xs[0])

    def lookup(self, mask, x, y):
        """mask at the lattice node nearest each point (False off the lattice)."""
        i = np.rint((np.asarray(x) - self.xs[0]) / self.g).astype(int)
        j = np.rint((np.asarray(y) - self.ys[0]) / self.g).astype(int)
        ok = (i >= 0) & (i < self.xs.size) & (j >= 0) & (j < self.ys.size)
        out = np.zeros(np.shape(x), bool)
        out[ok] = mask[j[ok], i[ok]]
        return out


@dataclass
class SteepPlan:
    runs: list  # tool-tip polylines, cutting order
    waterline_runs: int = 0
    zigzag_runs: int = 0
    levels: int = 0
    level_step: float = 0.0
    stepover: float = 0.0
    steep_fraction: float = 0.0
    notes: list = field(default_factory=list)


def tip_field(sampler, cutter: Cutter, g: float) -> TipField:
    x0, x1, y0, y1 = sampler.bounds
    xs = np.arange(x0, x1 + g / 2, g)
    ys = np.arange(y0, y1 + g / 2, g)
    origins = np.column_stack([np.full(ys.size, x0), ys])
    tip = drop_lines(sampler, cutter, origins, (1.0, 0.0), xs.size, g)
    X, Y = np.meshgrid(xs, ys)
    tip = np.where(sampler.part_distance(X, Y) <= 1e-9, tip, np.nan)
    gy, gx = np.gradient(np.where(np.isfinite(tip), tip, np.nanmin(tip)), g)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    return TipField(xs, ys, tip, np.where(np.isfinite(tip), slope, 0.0))


def regions(field: TipField, st: SteepSettings, within=None):
    """(steep, shallow) masks on the lattice: overlapping by overlap_deg in slope and
    `blend` mm in the plane, together covering every on-part node (of `within`)."""
    on = np.isfinite(field.tip) if within is None else (np.isfinite(field.tip) & within)
    grow = max(1, int(np.ceil(st.blend / field.g)))
    disc = _disc(grow)
    steep = on & ndimage.binary_dilation(field.slope_deg >= st.threshold_deg - st.overlap_deg, disc)
    # the zig-zag's band reaches into the walls only up to 15 degrees past its own limit: a pass
    # climbing an 84-degree wall stands on the drop-cutter's least accurate contacts (benches/steep.py
    # measured 0.038 mm gouges there with the band unbounded)
    shallow = (
        on
        & ndimage.binary_dilation(field.slope_deg < st.threshold_deg + st.overlap_deg, disc)
        & (field.slope_deg < st.threshold_deg + st.overlap_deg + SEAM_DEG)
    )
    return steep, shallow


def _disc(r):
    J, I = np.mgrid[-r : r + 1, -r : r + 1]
    return I * I + J * J <= r * r


def shallow_stepover(cutter: Cutter, scallop: float, slope_deg: float) -> float:
    if cutter.kind == "flat":
        # a flat bottom's riser on a slope m is m x stepover
        return float(max(scallop / np.tan(np.radians(slope_deg)), 0.05))
    a = cutter.radius - cutter.corner_radius
    return float(
        min(
            2 * a + ball_stepover(cutter.corner_radius, min(scallop, cutter.corner_radius), slope_deg),
            flat_stepover(cutter, scallop),
        )
    )


def _orient(field: TipField, line):
    """Higher tip field on the left of the direction of travel (one sense for every loop)."""
    if len(line) < 2:
        return line
    mid = 0.5 * (line[0] + line[1])
    t = line[1] - line[0]
    n = np.array([-t[1], t[0]]) / max(np.hypot(*t), 1e-12)
    probe = mid + n * field.g
    i = int(np.clip(np.rint((probe[0] - field.xs[0]) / field.g), 0, field.xs.size - 1))
    j = int(np.clip(np.rint((probe[1] - field.ys[0]) / field.g), 0, field.ys.size - 1))
    i2 = int(np.clip(np.rint((mid[0] - n[0] * field.g - field.xs[0]) / field.g), 0, field.xs.size - 1))
    j2 = int(np.clip(np.rint((mid[1] - n[1] * field.g - field.ys[0]) / field.g), 0, field.ys.size - 1))
    left, right = field.tip[j, i], field.tip[j2, i2]
    return line[::-1] if np.isfinite(left) and np.isfinite(right) and left < right else line


def _split(line, inside):
    """The pieces of a polyline where `inside` holds; a closed loop wholly inside stays closed."""
    closed = len(line) > 2 and np.allclose(line[0], line[-1])
    if inside.all():
        return [line]
    if closed and inside.any():
        k = int(np.flatnonzero(~inside)[0])  # start the loop outside, so no piece is cut in two
        line = np.vstack([line[k:-1], line[: k + 1]])
        inside = np.concatenate([inside[k:-1], inside[: k + 1]])
    return [line[a:b] for a, b in true_runs(inside) if b - a >= 2]


def _resample(line, step):
    seg = np.hypot(*np.diff(line, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return line[:1]
    n = max(int(np.ceil(s[-1] / step)), 1)
    t = np.linspace(0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])])


def _drop_runs(sampler, st: SteepSettings, lines):
    """XY polylines -> gouge-free tool-tip runs (dropped, refined, thinned)."""
    if not lines:
        return []
    pts = np.vstack(lines)
    z = drop_points(sampler, st.cutter, pts[:, 0], pts[:, 1], st.resolution)
    runs, k = [], 0
    for ln in lines:
        runs.append(np.column_stack([ln, z[k : k + len(ln)]]))
        k += len(ln)
    assert st.chord is not None  # set by SteepSettings.__post_init__
    tol = refine_tolerance(st.chord)
    runs = refine(sampler, st.cutter, runs, tol, 0.0, st.resolution)
    out = []
    for r in runs:
        keep = np.zeros(len(r), bool)
        keep[[0, -1]] = True
        # a point dropped sideways on a wall of slope theta is a vertical error of
        # tan(theta) times the sideways one: thin with a tenth of the chord, then
        # check the thinned moves' middles once more
        out.append(reduce_polyline(r, st.chord / 10, keep))
    return refine(sampler, st.cutter, out, tol, 0.0, st.resolution)


def waterlines(sampler, st: SteepSettings, field: TipField, steep):
    """(XY polylines in cutting order, levels, dz): top level first, each level's pieces nearest-first."""
    if not steep.any():
        return [], 0, 0.0
    dz = level_step(st.cutter, st.scallop, steepest(field, steep))
    lo, hi = float(np.nanmin(field.tip[steep])), float(np.nanmax(field.tip[steep]))
    # the levels span the steep region evenly, the lowest FOOT above its lowest tip: a wall
    # standing on a floor is cut to its foot by a loop beside the crease where the cutter,
    # resting on the floor, touches the wall with its side. A lowest level below the floor
    # has no contour, and the band of wall between the crease and the level above it kept
    # up to a level step of scallop (benches/steep.py: 0.119 mm at an 85-degree wall's foot).
    # Not on the crease itself: there the drop-cutter's search can miss the wall behind
    # the floor's contact (0.026 mm low, a gouge), a hair above it cannot.
    n = max(int(np.ceil((hi - lo) / dz - 1e-9)), 1)
    levels = np.linspace(hi - 1e-6, lo + min(FOOT, dz / 4), n + 1)
    by_level = []
    for z in levels:
        pieces = []
        for ln in contours(field.xs, field.ys, field.tip, float(z)):
            for piece in _split(ln, field.lookup(steep, ln[:, 0], ln[:, 1])):
                if np.sum(np.hypot(*np.diff(piece, axis=0).T)) >= 2 * st.resolution:
                    pieces.append(_resample(_orient(field, piece), st.resolution))
        by_level.append(pieces)
    on_level(sampler, st, field.g, [(p, z) for z, ps in zip(levels, by_level) for p in ps])
    out, at = [], None
    for pieces in by_level:
        while pieces:  # nearest piece next; a closed loop starts where it is nearest
            if at is None:
                k = 0
            else:
                k = int(np.argmin([np.min(np.hypot(*(p - at).T)) for p in pieces]))
            p = pieces.pop(k)
            if at is not None and len(p) > 2 and np.allclose(p[0], p[-1], atol=1e-6):
                m = int(np.argmin(np.hypot(*(p - at).T)))
                p = np.vstack([p[m:-1], p[: m + 1]])
            out.append(p)
            at = p[-1]
    return out, len(levels), dz


def raster(sampler, st: SteepSettings, field: TipField, shallow, stepover):
    """Zig-zag XY polylines over the shallow region, passes `stepover` apart."""
    if not shallow.any():
        return []
    e1, e2, (t0, t1), (s0, s1) = pass_frame(sampler, st.angle, 0.0)
    k = max(int(np.ceil((s1 - s0) / stepover - 1e-9)), 1)
    passes = np.linspace(s0, s1, k + 1)
    n = int(np.ceil((t1 - t0) / st.resolution - 1e-9)) + 1
    along = t0 + st.resolution * np.arange(n)
    out = []
    for p, s in enumerate(passes):
        pts = along[:, None] * e1[None, :] + s * e2[None, :]
        keep = field.lookup(shallow, pts[:, 0], pts[:, 1]) & (
            sampler.part_distance(pts[:, 0], pts[:, 1]) <= 1e-9
        )
        pieces = [pts[a:b] for a, b in true_runs(keep) if b - a >= 2]
        if p % 2 == 1:
            pieces = [q[::-1] for q in pieces[::-1]]
        out.extend(pieces)
    return out


def plan(sampler, st: SteepSettings, within=None, field: TipField | None = None) -> SteepPlan:
    """Steep and shallow finishing of the part (or of the lattice mask `within`)."""
    st.check()
    check_fits(sampler, st.cutter)
    field = tip_field(sampler, st.cutter, st.grid) if field is None else field
    steep, shallow = regions(field, st, within)
    wl, nlev, dz = waterlines(sampler, st, field, steep)
    so = shallow_stepover(st.cutter, st.scallop, st.threshold_deg + st.overlap_deg)
    zz = raster(sampler, st, field, shallow, so)
    runs = _drop_runs(sampler, st, zz + wl)
    on = np.isfinite(field.tip) if within is None else np.isfinite(field.tip) & within
    frac = float(steep.sum() / max(on.sum(), 1))
    notes = [
        f"steep and shallow at {st.threshold_deg:g} deg (overlap {st.overlap_deg:g} deg, "
        f"{st.blend:g} mm): {len(zz)} zig-zag runs {so:.3f} mm apart, {len(wl)} waterline runs "
        f"on {nlev} levels {dz:.3f} mm apart, scallop {st.scallop:g} mm"
    ]
    return SteepPlan(runs, len(wl), len(zz), nlev, dz, so, frac, notes)


def rest_region(sampler, field: TipField, larger: Cutter, smaller: Cutter, rest_tol: float):
    """Lattice mask of the axis positions for the smaller cutter: within its radius of
    where the larger one's opening stands more than rest_tol above the design."""
    from .opening import Opening

    x0, x1, y0, y1 = sampler.bounds
    op = Opening.over(sampler, larger, field.g, x0, y0, x1, y1)
    X, Y = np.meshgrid(field.xs, field.ys)
    design = sampler.z(X, Y)
    left = (op.at(X, Y) - design > rest_tol) & sampler.on_part(X, Y)
    grow = int(np.ceil((smaller.radius + field.g) / field.g))
    return ndimage.binary_dilation(left, _disc(grow))


def plan_rest(sampler, st: SteepSettings, larger: Cutter, rest_tol: float | None = None) -> SteepPlan:
    """Rest machining with st.cutter after `larger`: steep and shallow, only where `larger` could not reach."""
    if st.cutter.radius >= larger.radius:
        raise SettingError(
            "rest",
            f"the rest tool ({st.cutter.name}) must be smaller than the tool before it ({larger.name})",
        )
    tol = st.scallop if rest_tol is None else rest_tol
    st.check()
    field = tip_field(sampler, st.cutter, st.grid)
    within = rest_region(sampler, field, larger, st.cutter, tol)
    p = plan(sampler, st, within, field) if within.any() else SteepPlan([], notes=[])
    p.notes = [
        f"rest machining after {larger.name}: where it stays more than {tol:g} mm above the design "
        f"({within.mean() * 100:.1f} % of the part's box)"
    ] + p.notes
    return p
