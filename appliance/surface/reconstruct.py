"""Waterlines at levels -> height map: the surface room's main entry point.

    reconstruct(waterlines, grid, options) -> Reconstruction

Steps, each in its own module:
1. check the input (slices.check_waterlines): sort, de-duplicate, clear errors;
2. displacement (displacement.py): nominal -> true levels from the areas the
   waterlines enclose, when the tank's area is given;
3. walls (slices.mark_walls): waterline stretches that stay put between levels;
4. first-exposure heights and the regularised grid fit (gridfit.py) on an
   internal lattice of ~240 nodes a side; the smoothing length is chosen by
   cross-validation on held-out levels;
5. meniscus (meniscus.py): that fit is of the contact lines, the apparent
   surface top - h(beta); the top is solved from it, and each contact point's
   rise puts it back by the perspective for the next pass;
6. the output grid sampled from the lattice, with each cell's source and
   uncertainty in mm (uncertainty.py).

The dissertation's methods stay selectable (options.method = "nearest",
"spline", "lsq1".."lsq3", "captured") on the same checked, corrected waterlines.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ..errors import SettingError
from . import seed as seed_methods
from .gridfit import (
    DIRECT_MAX,
    FitProblem,
    Lattice,
    area_weights,
    bilinear,
    exposed_mask,
    fill_nearest,
    first_exposure,
    flat_faces,
    occluded_nodes,
    point_data,
    tilt_crossed_faces,
)
from .heightmap import HeightMap
from .meniscus import (
    bracket_dewetted_faces,
    contact_points,
    depression_depth,
    dewetted_nodes,
    pinned_rims_as_walls,
    place_dewetted_faces,
    top_from_apparent,
)
from .slices import (
    Perspective,
    check_waterlines,
    mark_silhouettes,
    mark_walls,
    outline_bounds,
    unproject_rims,
)
from .uncertainty import CellEvidence, node_uncertainty
from .uncertainty import to_output as uncertainty_to_output

METHODS = ("fit",) + seed_methods.METHODS
PASSES = 3  # with walls seen in perspective or a tank given: each later fit takes the true
# levels, each wall edge's height and the emerged volume from the one before


@dataclass(frozen=True)
class GridSpec:
    """Output lattice: bounds (xmin, xmax, ymin, ymax) in mm and either n = (nx, ny)
    nodes spanning the bounds inclusive (the dissertation's 50 x 50) or a spacing in mm.
    bounds None: the part's outline as the waterlines show it (after the perspective)."""

    bounds: tuple | None
    n: tuple | None = None
    spacing_mm: float | None = None

    def axes(self):
        xmin, xmax, ymin, ymax = map(float, self.bounds)
        if not (xmax > xmin and ymax > ymin):
            raise SettingError("grid", f"empty bounds {self.bounds}")
        if (self.n is None) == (self.spacing_mm is None):
            raise SettingError("grid", "give either n = (nx, ny) or spacing_mm, not both or neither")
        if self.n is not None:
            nx, ny = (self.n, self.n) if np.isscalar(self.n) else self.n
            if int(nx) < 2 or int(ny) < 2:
                raise SettingError("grid", f"need at least 2 x 2 nodes, got {self.n}")
            return np.linspace(xmin, xmax, int(nx)), np.linspace(ymin, ymax, int(ny))
        s = float(self.spacing_mm)
        if not (s > 0 and math.isfinite(s)):
            raise SettingError("grid", f"spacing must be a positive number of mm, got {self.spacing_mm!r}")
        nx = int(math.floor((xmax - xmin) / s + 1e-9)) + 1
        ny = int(math.floor((ymax - ymin) / s + 1e-9)) + 1
        if nx * ny > 25_000_000:
            raise SettingError("grid", f"{nx} x {ny} nodes is too many (over 25 million)")
        return xmin + s * np.arange(nx), ymin + s * np.arange(ny)


@dataclass
class ReconstructOptions:
    method: str = "fit"
    smoothing_mm: float | None = None  # thin-plate smoothing length; None = cross-validate
    wall_tol_mm: float = 0.03  # a waterline moving less than this between levels is a wall
    lattice_max: int = 241  # internal lattice nodes per side (fit size)
    point_weight: float = 0.3  # weight of a raw waterline point vs a first-exposure node height
    footprint_tol_mm: float | None = None  # default: a quarter of the lattice spacing
    tank_area_mm2: float | None = None  # displacement correction when given
    meniscus: object = None  # meniscus.MeniscusModel when the correction is wanted
    perspective: Perspective | None = None  # camera foot and height: walls seen by their raised edges
    pixel_mm: float = 0.0  # the camera's pixel on the liquid plane (waterline placement)
    explain_uncertainty: bool = False  # diagnostics["uncertainty_terms"]: each term on the output grid


@dataclass
class Reconstruction:
    heightmap: HeightMap
    smoothing: float | None
    diagnostics: dict = field(default_factory=dict)


# -- lattice ------------------------------------------------------------------------


def _lattice_for(xo, yo, lattice_max):
    """A lattice that contains the output nodes when the output is coarse, else its own."""
    n = max(xo.size, yo.size)
    if n <= lattice_max:
        # a coarse output (the dissertation's 50 x 50) is fitted on a lattice twice as fine,
        # small enough to solve directly: the waterline points then pin the surface between
        # the output nodes instead of being smeared over a whole output cell
        r = 2 if ((xo.size - 1) * 2 + 1) * ((yo.size - 1) * 2 + 1) <= DIRECT_MAX else 1
        lx = np.linspace(xo[0], xo[-1], (xo.size - 1) * r + 1)
        ly = np.linspace(yo[0], yo[-1], (yo.size - 1) * r + 1)
        return Lattice(lx, ly), r
    ext = max(xo[-1] - xo[0], yo[-1] - yo[0])
    h = ext / (lattice_max - 1)
    nx = int(math.ceil((xo[-1] - xo[0]) / h)) + 1
    ny = int(math.ceil((yo[-1] - yo[0]) / h)) + 1
    return Lattice(np.linspace(xo[0], xo[-1], nx), np.linspace(yo[0], yo[-1], ny)), None


def _to_output(lat, zl, r, xo, yo):
    if r is not None:
        return zl[::r, ::r]
    # cubic resampling of a field filled past its edge, so NaN never enters the spline
    filled = fill_nearest(zl)
    fi = (xo - lat.x[0]) / lat.hx
    fj = (yo - lat.y[0]) / lat.hy
    FJ, FI = np.meshgrid(fj, fi, indexing="ij")
    return ndimage.map_coordinates(filled, [FJ, FI], order=3, mode="nearest")


# -- the fit --------------------------------------------------------------------------


BRACKET_SLACK_LEVELS = 2  # one held sample 4's rim nodes 1.4 mm low (clean Ea 0.0220 -> 0.0174 with two)


def _bracket(z, first, slices, rise_max=0.0):
    """Clamp each node between the level where it came out and the one above it.

    A node exposed first at frame k and still under at frame k - 1 lies in
    between, whatever the fit's smoothness would rather do (extrapolating into
    a gap beside a wall, say). Meniscus-corrected heights widen the bracket, and
    with a meniscus a node may stand up to its largest rise above the level that
    still covered it (`rise_max`): the ink climbs a rim and keeps it under (sample
    4's 39 mm summit rim, exposed at 36 mm, was clamped there, 3 mm low).
    """
    K = len(slices)
    top = next(k for k, s in enumerate(slices) if not s.empty)
    # the rises of the level-curve points (a wall point's says nothing about the top)
    curves = [s.level_curve() if not s.empty else s for s in slices]
    lo_rise = [float(np.min(c.z - c.level)) if not c.empty else 0.0 for c in curves]
    hi_rise = [float(np.max(c.z - c.level)) if not c.empty else 0.0 for c in curves]
    lv = np.array([s.level for s in slices] + [-np.inf])
    lo = np.array([lv[k] + min(lo_rise[k], 0.0) for k in range(K)] + [-np.inf])
    hi = np.array([np.inf] + [lv[k - 1] + max(hi_rise[k - 1], rise_max, 0.0) for k in range(1, K)] + [np.inf])
    hi[top] = np.inf
    # BRACKET_SLACK_LEVELS of slack each way: where waterlines crowd (a saddle's corner, a
    # face rising at 8 to a rim) the side of a node is not sure; the bracket is there to stop
    # wild extrapolation, not to fine-tune
    n = BRACKET_SLACK_LEVELS
    lo_s = np.r_[lo[n:], [-np.inf] * n]
    hi_s = np.r_[[np.inf] * n, hi[:-n]]
    hi_s[K] = np.inf  # never exposed (nodes on the outline itself): no bracket
    return np.clip(z, lo_s[first], hi_s[first])


def _fit_nodes(problem, z_nodes, pts, zp, length_mm, point_weight, prior=None):
    """The regularised fit; `prior` (NaN where none): node heights for the faces nothing
    else places (faces that came out at once: _flat_prior)."""
    lat = problem.lat
    lam = length_mm**4 / (lat.hx * lat.hy)  # data are one per node: density 1 / cell area
    blocks = [problem.node_rows(z_nodes, 1.0)]
    if point_weight > 0 and len(pts):
        blocks.append(problem.data_rows(pts, zp, point_weight))
    start = z_nodes
    if prior is not None:
        blocks.append(problem.node_rows(prior, FLAT_PRIOR_WEIGHT))
        start = np.where(np.isfinite(z_nodes), z_nodes, prior)
    return problem.solve(blocks, lam, x0=problem.gap_fill(start))


def _cross_validate(problem, z_fe, pts, zp, point_weight, seed=0):
    """Hold out a tenth of the first-exposure nodes, fit on the rest, score on them."""
    rng = np.random.default_rng(seed)
    have = np.flatnonzero(np.isfinite(z_fe.ravel()) & problem.active.ravel())
    if have.size < 50:
        return None, []
    held = rng.choice(have, size=max(5, have.size // 10), replace=False)
    train = z_fe.copy()
    train.ravel()[held] = np.nan
    h = min(problem.lat.hx, problem.lat.hy)
    curve = []
    for mult in (0.5, 1, 2, 4):
        z = _fit_nodes(problem, train, pts, zp, mult * h, point_weight)
        r = z.ravel()[held] - z_fe.ravel()[held]
        curve.append((mult * h, float(np.sqrt(np.mean(r**2)))))
    best = min(curve, key=lambda c: c[1])[0]
    return best, curve


def _seed_method(name, slices, xo, yo):
    pts = np.vstack([np.column_stack([s.P, s.z]) for s in slices if not s.empty])
    levels = [s.level for s in slices]
    exposed = None
    if name == "captured":
        lat = Lattice(xo, yo)
        exposed = np.stack([exposed_mask(lat, s) for s in slices])
    return seed_methods.run_method(name, xo, yo, pts, levels, exposed)


def _corrected_levels(seen, opt, diag, lat=None, z=None, levels=None):
    """Walls found and their edges put back where the walls are, then the displacement's
    true levels. From the second pass on, the previous pass's true levels (`levels`)
    place the walls, and its fit (lat, z) gives each edge's height and the emerged volume."""
    nominal = [s.level for s in seen]
    slices = seen
    if levels is not None:
        slices = [s.at_level(L) for s, L in zip(seen, levels)]
    if opt.perspective is not None:
        # walls are seen by their top edges, raised and pushed out by the perspective:
        # find them and put them back before anything measures the outline or areas
        # the true level steps: unknown before the first fit (the ink drops up to 2.5x the
        # nominal step as the part comes out), known to within a third after it
        rng = (1.0, 2.5) if levels is None else (0.75, 1.33)
        rng = rng if opt.tank_area_mm2 else (1.0, 1.0)
        diag["wall_points"] = mark_walls(slices, opt.wall_tol_mm, opt.perspective, rng)
        if levels is not None or not opt.tank_area_mm2:
            # a ray's height above the ink is the level difference: with the ink still to be
            # corrected for what the part displaces (first pass) it is not known well enough
            diag["silhouette_points"] = mark_silhouettes(slices, opt.perspective)
        rise = float(opt.meniscus.rise(np.pi / 2)) if opt.meniscus is not None else 0.0
        rim_height = _rim_height(lat, z) if z is not None else None
        slices = unproject_rims(slices, opt.perspective, opt.wall_tol_mm, rim_height, max(rise, 0.0), rng)
    if opt.tank_area_mm2:
        from .displacement import correct_slices, levels_from_surface

        true = None
        if z is not None:
            true = levels_from_surface(
                nominal, z, lat.hx * lat.hy, opt.tank_area_mm2, weights=area_weights(lat, slices)
            )
            true = _relaxed_levels(levels, true, slices, opt.tank_area_mm2)
        base = [s.at_level(L) for s, L in zip(slices, nominal)]
        slices, disp = correct_slices(base, opt.tank_area_mm2, true)
        disp["from"] = "fitted surface" if z is not None else "waterline areas"
        diag["displacement"] = disp
    return slices


def _relaxed_levels(previous, update, slices, tank_area_mm2):
    """The next pass's true levels: a level that is d too high raises the fit by about d
    over the part's waterline area a, the volume by a d, and the update drops the level
    by a d / A_tank: the passes overshoot by a / A_tank each time (sample 2: the fit's
    mean error went +0.15, +0.04, -0.037 mm). Stepping 1 / (1 + a / A_tank) of the way
    takes the overshoot out."""
    if previous is None:
        return update
    a = np.array([max(s.area(), 0.0) for s in slices]) / tank_area_mm2
    previous = np.asarray(previous, float)
    return previous + (np.asarray(update, float) - previous) / (1.0 + a)


def _resample(old: Lattice, z, new: Lattice):
    """A field (NaN off the part) read on another lattice: the next pass's rise must sit
    where the surface is, not where the old lattice's indices fall."""
    X, Y = np.meshgrid(new.x, new.y)
    P = np.column_stack([X.ravel(), Y.ravel()])
    on = bilinear(old, np.isfinite(z).astype(float), P) > 0.5
    v = bilinear(old, fill_nearest(z), P)
    return np.where(on & np.isfinite(v), v, np.nan).reshape(X.shape)


FLAT_FAR_NODES = 3  # lattice spacings from any waterline: a node on a face that came out at once,
FLAT_FAR_MM = 2.0  # and at least this far (a small part's fine lattice: sample 4's waterlines
# a node or two apart on its 20 mm rims would take its faces for flat)
FLAT_EDGE_MM = 0.5  # nor on the outline: sample 4's rim nodes first come out levels late
FLAT_PRIOR_WEIGHT = 1.0  # such a node's mid-bracket height, as a first-exposure height weighs
RIM_INSET = 2  # lattice nodes: nearer its outline than this the fit is extrapolating


def _rim_height(lat, z):
    """The fit's height at wall edges: the surface continued to the edge, linearly, from
    the nearest node at least RIM_INSET nodes inside the fit's outline.

    The fit's own nodes next to the outline are the least sure (their first exposure is
    the wall's waterline, a level step wide), and reading them fed a loop: a rim read low
    puts the edge further out (less of the perspective taken off), the outline grows, and
    the nodes beyond the true wall come out of the lowest frames, lower still (sample 2's
    x = 100 rim read 13.1 mm for 15.7, 0.5 mm inside the wall)."""
    filled = fill_nearest(z)
    core = ndimage.binary_erosion(np.isfinite(z), iterations=RIM_INSET, border_value=0)
    if core.sum() < 9:
        core = np.isfinite(z)
    gy, gx = np.gradient(filled, lat.y, lat.x)
    _, (qj, qi) = ndimage.distance_transform_edt(~core, sampling=(lat.hy, lat.hx), return_indices=True)

    def at(P):
        fi, fj = lat.to_index(P)
        i = np.clip(np.round(fi).astype(int), 0, lat.shape[1] - 1)
        j = np.clip(np.round(fj).astype(int), 0, lat.shape[0] - 1)
        inner = core[j, i]
        Q = np.column_stack([np.clip(P[:, 0], lat.x[0], lat.x[-1]), np.clip(P[:, 1], lat.y[0], lat.y[-1])])
        out = bilinear(lat, filled, Q)
        cj, ci = qj[j, i], qi[j, i]
        ext = filled[cj, ci] + gx[cj, ci] * (P[:, 0] - lat.x[ci]) + gy[cj, ci] * (P[:, 1] - lat.y[cj])
        return np.where(inner, out, ext)

    return at


def _flat_prior(z, z_mid, mid, flat, tilted=None):
    """Mid-bracket heights for the faces that came out at once where the fit cannot place
    them: a face (a connected patch of such nodes) on which the fit leaves the bracket
    anywhere by more than a quarter of it has nothing to hold it (a plateau ringed by
    walls: the thin plate took it 20 mm up). Where the fit stays inside, a slope it
    continues from the waterlines around (a dome's corner between the last level
    curve and the rim) knows better than the middle - except on a face a single level
    curve crosses (`tilted`, gridfit.tilt_crossed_faces): the thin plate bends it any way
    it likes at no cost, and the plane through that curve is all the frames tell.
    None when no face needs it."""
    if not mid.any():
        return None
    lo, hi = flat
    slack = 0.25 * (hi - lo)
    out = mid & ((z < lo - slack) | (z > hi + slack))
    if tilted is not None:
        out |= mid & tilted
    if not out.any():
        return None
    labels, _ = ndimage.label(mid)
    bad = np.isin(labels, np.unique(labels[out]))
    return np.where(bad, z_mid, np.nan)


def _fit_pass(lat, slices, opt, ftol, length, rise):
    """First exposure and the fit (smoothing cross-validated on the first pass). With a
    meniscus the fit is of the contact lines - where the last pass's rise field says they
    really are - and the top is solved from it (meniscus.top_from_apparent)
    -> (z, z_fe, first, footprint, slices at their heights, length, curve or None, rise)."""
    if opt.meniscus is not None:
        slices = pinned_rims_as_walls(slices, opt.meniscus, opt.wall_tol_mm)
    observed = slices
    if opt.meniscus is not None and rise is not None:
        slices, _ = contact_points(observed, lat, rise, opt.meniscus)
    z_fe, first, footprint = first_exposure(lat, slices, ftol)
    placed = z_fe
    if opt.meniscus is not None:
        placed = place_dewetted_faces(lat, z_fe, first, footprint, slices, opt.meniscus)
    h = max(lat.hx, lat.hy)
    z_mid, mid, flat = flat_faces(
        lat, slices, z_fe, first, max(FLAT_FAR_NODES * h, FLAT_FAR_MM), max(2 * h, FLAT_EDGE_MM)
    )
    tilted = tilt_crossed_faces(lat, slices, z_mid, mid, first, max(FLAT_FAR_NODES * h, FLAT_FAR_MM))
    if not footprint.any():
        raise SettingError("grid", "the grid does not cover the part: no node is inside any waterline")
    problem = FitProblem(lat, footprint)
    pts, zp = point_data(slices, 0.5 * min(lat.hx, lat.hy))
    curve = None
    if length is None:
        length, curve = _cross_validate(problem, placed, pts, zp, opt.point_weight)
        if length is None:
            length = min(lat.hx, lat.hy)
    z = _fit_nodes(problem, placed, pts, zp, length, opt.point_weight)
    prior = _flat_prior(z, z_mid, mid & ~np.isfinite(placed), flat, tilted)
    if prior is not None:
        z = _fit_nodes(problem, placed, pts, zp, length, opt.point_weight, prior)
    if opt.meniscus is not None:
        z = bracket_dewetted_faces(lat, z, z_fe, first, footprint, slices, opt.meniscus)
        faces = dewetted_nodes(lat, z_fe, first, footprint, slices, opt.meniscus)
        top = top_from_apparent(lat, z, footprint, opt.meniscus, faces)
        rise = top - z
        z = top
        _, slices = contact_points(observed, lat, rise, opt.meniscus)
    return z, z_fe, first, footprint, slices, length, curve, rise, flat


def reconstruct(waterlines, grid: GridSpec, options: ReconstructOptions | None = None) -> Reconstruction:
    opt = options or ReconstructOptions()
    if opt.method not in METHODS:
        raise SettingError("method", f"unknown surface method {opt.method!r}; known: {', '.join(METHODS)}")
    t0 = time.perf_counter()
    xo, yo = grid.axes() if grid.bounds is not None else (None, None)
    slices, notes = check_waterlines(waterlines)
    diag = {"notes": notes, "levels_in_mm": [s.level for s in slices]}
    camera = opt.perspective
    if camera is None:
        diag["wall_points"] = mark_walls(slices, opt.wall_tol_mm)
    seen = slices
    slices = _corrected_levels(seen, opt, diag)
    auto_bounds = grid.bounds is None
    if auto_bounds:
        grid = GridSpec(outline_bounds(slices), grid.n, grid.spacing_mm)
        xo, yo = grid.axes()
        diag["bounds"] = grid.bounds
    diag["points"] = int(sum(len(s.P) for s in slices))
    if opt.method != "fit":
        if opt.meniscus is not None:
            from .meniscus import correct_slices_from_spacing

            slices = correct_slices_from_spacing(slices, opt.meniscus)
        hm = _seed_method(opt.method, slices, xo, yo)
        diag["seconds"] = time.perf_counter() - t0
        return Reconstruction(hm, None, diag)

    lat, r = _lattice_for(xo, yo, opt.lattice_max)
    ftol = opt.footprint_tol_mm if opt.footprint_tol_mm is not None else 0.25 * min(lat.hx, lat.hy)
    length, curve = opt.smoothing_mm, []
    walls = camera is not None and any(s.wall.any() for s in slices if not s.empty)
    passes = PASSES if walls or opt.tank_area_mm2 or opt.meniscus is not None else 1
    z = rise = None
    corrected = slices
    for _ in range(passes):
        if z is not None:
            # second pass: each wall edge's height and the emerged volume from the first fit
            true = diag["displacement"]["true_mm"] if "displacement" in diag else None
            slices = _corrected_levels(seen, opt, diag, lat, np.where(footprint, z, np.nan), true)
            corrected = slices
            if auto_bounds:  # the outline is surer now: the grid follows it
                grid = GridSpec(outline_bounds(slices), grid.n, grid.spacing_mm)
                xo, yo = grid.axes()
                diag["bounds"] = grid.bounds
                old, (lat, r) = lat, _lattice_for(xo, yo, opt.lattice_max)
                rise = None if rise is None else _resample(old, rise, lat)
        z, z_fe, first, footprint, slices, length, cv, rise, flat = _fit_pass(
            lat, slices, opt, ftol, length, rise
        )
        curve = cv if cv is not None else curve
    diag["lattice"] = {"nx": lat.x.size, "ny": lat.y.size, "hx_mm": lat.hx, "hy_mm": lat.hy}
    # the bracket guards the gaps the fit extrapolates into; nodes with data keep the fit
    rise_max = (
        0.0 if opt.meniscus is None else max(float(opt.meniscus.rise(np.pi / 2)), 0.0)
    )  # h grows with the slope
    z = np.where(np.isfinite(z_fe), z, _bracket(z, first, slices, rise_max))
    # a face that came out at once lies between its two levels, whatever the fit says
    # (an ink that dewets stands its depression above a flat face it has just left: the
    # face is that much below its levels, meniscus.place_dewetted_faces)
    sure = np.isfinite(flat[0])
    sink = depression_depth(opt.meniscus) if opt.meniscus is not None else 0.0
    z[sure] = np.clip(z[sure], flat[0][sure] - sink, flat[1][sure] + rise_max)
    z = np.where(footprint, z, np.nan)
    exposed = np.stack([exposed_mask(lat, s) for s in slices])
    # the first-exposure heights are of the contact lines; with a meniscus the fit is of the top
    z_fe_top = z_fe if rise is None else z_fe + np.where(np.isfinite(rise), rise, 0.0)
    explain = {} if opt.explain_uncertainty else None
    src, sig = node_uncertainty(
        CellEvidence(
            lat,
            z,
            z_fe_top,
            first,
            footprint,
            slices,
            exposed,
            opt.pixel_mm,
            None,
            rise,
            opt.meniscus.capillary_length_mm if opt.meniscus else 0.0,
        ),
        explain,
    )
    if explain is not None:
        diag["uncertainty_terms"] = {
            k: uncertainty_to_output(lat, src, v, r, xo, yo)[1] for k, v in explain.items()
        }
    zo = _to_output(lat, z, r, xo, yo)
    srco, so = uncertainty_to_output(lat, src, sig, r, xo, yo)
    fo = _to_output(lat, footprint.astype(float), r, xo, yo) > 0.5
    zo = np.where(fo, zo, np.nan)
    so = np.where(fo, so, np.nan)
    srco = np.where(fo, srco, -1).astype(np.int8)
    # cells a face above the ink hid in some frame (their heights are from other frames)
    occluded = occluded_nodes(lat, seen, corrected) & footprint
    diag["occluded_nodes"] = int(occluded.sum())
    diag["occluded_cells"] = (_to_output(lat, occluded.astype(float), r, xo, yo) > 0.5) & fo
    diag.update(
        {
            "cross_validation": curve,
            "smoothing_mm": length,
            "first_exposure_nodes": int(np.isfinite(z_fe).sum()),
            "cap_nodes": int(
                (footprint & (first == next(k for k, s in enumerate(slices) if not s.empty))).sum()
            ),
            "seconds": time.perf_counter() - t0,
        }
    )
    srco, so = _occluded_cells(srco, so, diag.get("occluded_cells"), slices)
    return Reconstruction(HeightMap(xo, yo, zo, so, srco), length, diag)


def _occluded_cells(src, sig, occluded, slices):
    """Cells under a face that hid the waterline behind it (diagnostics["occluded_cells"],
    a mask on the output grid): their height comes from the frames where they were still
    seen, so it is known to within a level step (uniform over it: step / sqrt(12))."""
    if not isinstance(occluded, np.ndarray) or occluded.shape != src.shape or not occluded.any():
        return src, sig
    from .uncertainty import OCCLUDED

    levels = np.array([s.level for s in slices])
    step = float(np.median(-np.diff(levels))) if levels.size > 1 else 0.0
    on = occluded & (src >= 0)
    src = np.where(on, OCCLUDED, src).astype(np.int8)
    sig = np.where(on, np.maximum(np.nan_to_num(sig), step / math.sqrt(12.0)), sig)
    return src, sig
