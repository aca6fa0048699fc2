"""Waterlines at levels -> height map: the surface room's main entry point.

    reconstruct(waterlines, grid, options) -> Reconstruction

Steps, each in its own module:
1. check the input (slices.check_waterlines): sort, de-duplicate, clear errors;
2. walls (perspective.mark_walls) and silhouettes (silhouettes.py): waterline
   stretches that stay put or move as the perspective says, and rims of faces
   that hide the waterline; their edges are put back (corrections.py);
3. displacement (displacement.py): nominal -> true levels from the areas the
   waterlines enclose, when the tank's area is given;
4. a pass of the fit (fitpass.py): first-exposure heights (exposure.py), the
   priors for faces that came out at once (flatfaces.py) and the regularised
   grid fit (gridfit.py) on an internal lattice (lattice.py) of ~240 nodes a
   side; the smoothing length is chosen by cross-validation on held-out nodes;
   after the last pass each node is held between what the frames saw for sure
   (inkbounds.py): out of the ink, and ink over it (behind a silhouette, the ray
   over the rim);
5. meniscus (contact_lines.py): that fit is of the contact lines, the apparent
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
from typing import Any

import numpy as np
from scipy import ndimage

from ..errors import SettingError
from . import seed as seed_methods
from .corrections import above_base, corrected_levels
from .dewetted import depression_depth
from .edges import beyond_outline, with_edge_nodes
from .fitpass import bracket_bounds, fit_pass, flat_face_rise, flat_far_mm
from .flatfaces import beside_faces
from .gridfit import DIRECT_MAX
from .heightmap import HeightMap
from .inkbounds import FAR_NODES, held, node_bounds, under_flat_ink
from .lattice import Lattice, bilinear, exposed_mask, fill_nearest
from .meniscus import MeniscusModel, correct_slices_from_spacing
from .perspective import Perspective, mark_walls, on_fallen_ink
from .pools import cover_held_pools, held_pools
from .registration import registered
from .rimrays import under_rim_rays
from .silhouettes import occluded_nodes
from .slices import check_waterlines, level_step, outline_bounds
from .uncertainty import OCCLUDED, WALL, CellEvidence, node_uncertainty
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
    # the ink's surface falls under a camera fixed to the tank (no overflow holds it): a frame
    # whose ink fell d is seen from H + d, its points (H + d) / H as far from the camera's foot
    ink_falls: bool = False
    meniscus: MeniscusModel | None = None  # the correction, when wanted
    perspective: Perspective | None = None  # camera foot and height: walls seen by their raised edges
    pixel_mm: float = 0.0  # the camera's pixel on the liquid plane (waterline placement)
    register_frames: bool = True  # frames moved back by their lateral stage play (registration.py)
    pair_memo: dict | None = None  # the frame pairs' shifts measured before (registration.pair_shifts)
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


def _seed_method(name, slices, xo, yo):
    pts = np.vstack([np.column_stack([s.P, s.z]) for s in slices if not s.empty])
    levels = [s.level for s in slices]
    exposed = None
    if name == "captured":
        lat = Lattice(xo, yo)
        exposed = np.stack([exposed_mask(lat, s) for s in slices])
    return seed_methods.run_method(name, xo, yo, pts, levels, exposed)


def _resample(old: Lattice, z, new: Lattice):
    """A field (NaN off the part) read on another lattice: the next pass's rise must sit
    where the surface is, not where the old lattice's indices fall."""
    X, Y = np.meshgrid(new.x, new.y)
    P = np.column_stack([X.ravel(), Y.ravel()])
    on = bilinear(old, np.isfinite(z).astype(float), P) > 0.5
    v = bilinear(old, fill_nearest(z), P)
    return np.where(on & np.isfinite(v), v, np.nan).reshape(X.shape)


def reconstruct(waterlines, grid: GridSpec, options: ReconstructOptions | None = None) -> Reconstruction:
    opt = options or ReconstructOptions()
    if opt.method not in METHODS:
        raise SettingError("method", f"unknown surface method {opt.method!r}; known: {', '.join(METHODS)}")
    t0 = time.perf_counter()
    auto_bounds = grid.bounds is None
    if not auto_bounds:
        grid.axes()  # a grid that cannot be is refused before any work
    slices, notes = check_waterlines(waterlines)
    diag: dict[str, Any] = {"notes": notes, "levels_in_mm": [s.level for s in slices]}
    camera = opt.perspective
    if opt.register_frames:
        foot, height = (camera.xy, camera.height_mm) if camera is not None else (None, None)
        slices, offsets = registered(slices, foot, height, opt.pair_memo)
        diag["frame_offsets_mm"] = float(np.max(np.hypot(*offsets.T), initial=0.0))
    if camera is None:
        diag["wall_points"] = mark_walls(slices, opt.wall_tol_mm)
    seen = slices
    seen, slices = above_base(seen, corrected_levels(seen, opt, diag), diag)
    as_seen = {s.level: s for s in seen}  # the points as the homography put them, by frame
    if auto_bounds:
        grid = GridSpec(outline_bounds(slices), grid.n, grid.spacing_mm)
        diag["bounds"] = grid.bounds
    xo, yo = grid.axes()
    diag["points"] = int(sum(len(s.P) for s in slices))
    if opt.method != "fit":
        if opt.meniscus is not None:
            slices = correct_slices_from_spacing(slices, opt.meniscus)
        hm = _seed_method(opt.method, slices, xo, yo)
        diag["seconds"] = time.perf_counter() - t0
        return Reconstruction(hm, None, diag)

    lat, r = _lattice_for(xo, yo, opt.lattice_max)
    ftol = opt.footprint_tol_mm if opt.footprint_tol_mm is not None else 0.25 * min(lat.hx, lat.hy)
    walls = camera is not None and any(s.wall.any() for s in slices if not s.empty)
    passes = PASSES if walls or opt.tank_area_mm2 or opt.meniscus is not None else 1
    corrected = slices
    fit = fit_pass(lat, slices, opt, ftol, opt.smoothing_mm, None, seen)
    curve = fit.curve if fit.curve is not None else []
    for _ in range(passes - 1):
        # each later pass: each wall edge's height and the emerged volume from the fit before
        true = diag["displacement"]["true_mm"] if "displacement" in diag else None
        if opt.ink_falls and camera is not None and true is not None:
            disp = diag["displacement"]
            seen = on_fallen_ink([as_seen[n] for n in disp["nominal_mm"]], disp["true_mm"], camera)
        slices = corrected_levels(seen, opt, diag, lat, np.where(fit.footprint, fit.z, np.nan), true)
        seen, slices = above_base(seen, slices, diag)
        corrected = slices
        rise = fit.rise
        if auto_bounds:  # the outline is surer now: the grid follows it
            grid = GridSpec(outline_bounds(slices), grid.n, grid.spacing_mm)
            xo, yo = grid.axes()
            diag["bounds"] = grid.bounds
            old, (lat, r) = lat, _lattice_for(xo, yo, opt.lattice_max)
            rise = None if rise is None else _resample(old, rise, lat)
        fit = fit_pass(lat, slices, opt, ftol, fit.length, rise, seen)
        curve = fit.curve if fit.curve is not None else curve
    z, z_fe, first, footprint, slices, length, _, rise, flat = fit
    diag["lattice"] = {"nx": lat.x.size, "ny": lat.y.size, "hx_mm": lat.hx, "hy_mm": lat.hy}
    # the bracket guards the gaps the fit extrapolates into; nodes with data keep the fit
    rise_max = (
        0.0 if opt.meniscus is None else max(float(opt.meniscus.rise(np.pi / 2)), 0.0)
    )  # h grows with the slope
    sink = depression_depth(opt.meniscus) if opt.meniscus is not None else 0.0
    lo, hi = bracket_bounds(first, slices, rise_max, sink)
    if opt.meniscus is not None:
        hi = np.minimum(hi, under_flat_ink(lat, first, slices, rise_max, opt.meniscus.capillary_length_mm))
    # a node a face hid is bounded by the frames that saw ink there, not by the rim put back
    known = node_bounds(lat, seen, corrected, first, footprint, rise_max, sink, camera)
    hi = np.where(known.hidden, known.ceiling, hi)
    runaway = ~np.isfinite(z_fe) & ~known.hidden & footprint & (z > hi)
    z = np.where(np.isfinite(z_fe) & ~known.hidden, z, np.clip(z, lo, hi))
    # a face that came out at once lies between its two levels, whatever the fit says
    # (an ink that dewets stands its depression above a flat face it has just left: the
    # face is that much below its levels, dewetted.place_dewetted_faces)
    sure = np.isfinite(flat[0])
    climb = flat_face_rise(opt.meniscus, flat, flat_far_mm(lat))
    z[sure] = np.clip(z[sure], flat[0][sure] - sink, flat[1][sure] + climb[sure])
    # and a node beside such a face that the fit ran away with (over its ceiling) is the face
    z = beside_faces(lat, z, runaway, first, sure, (lo, hi), flat_far_mm(lat))
    z = held(z, known)
    reach = z  # the fit beyond the footprint too: where the part's edge nodes come from
    z = np.where(footprint, z, np.nan)
    exposed = np.stack([exposed_mask(lat, s) for s in slices])
    # the first-exposure heights are of the contact lines; with a meniscus the fit is of the top
    z_fe_top = z_fe if rise is None else z_fe + np.where(np.isfinite(rise), rise, 0.0)
    explain: dict | None = {} if opt.explain_uncertainty else None
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
    edge = beyond_outline([s for s in slices if not s.empty], xo, yo, fo)
    if edge.any():  # the fit continued out is resampled only for a scan that has them
        ray = _rays_over_edge(edge, xo, yo, seen, corrected, camera, FAR_NODES * max(lat.hx, lat.hy))
        zo, so, srco = with_edge_nodes(zo, so, srco, edge, WALL, _to_output(lat, reach, r, xo, yo), ray)
    diag["edge_cells"] = int(edge.sum())
    hm = HeightMap(xo, yo, zo, so, srco)
    # a pocket that held ink: its floor never showed (pools.py)
    pools = held_pools([(t.level, s.loops) for s, t in zip(seen, corrected)], camera)
    if pools:
        hm, said = cover_held_pools(hm, pools, rise_max)
        diag["held_notes"] = said
        diag["held_pools"] = [
            {"centre_mm": p.centre, "area_mm2": p.area_mm2, "bracket_mm": p.bracket} for p in pools
        ]
    return Reconstruction(hm, length, diag)


def _rays_over_edge(edge, xo, yo, seen, corrected, camera, reach):
    """Per output node, the ray over a rim put back that passes over it, on the edge nodes
    (inf elsewhere and where none does)."""
    ray = np.full(edge.shape, np.inf)
    X, Y = np.meshgrid(xo, yo)
    ray[edge] = under_rim_rays(np.column_stack([X[edge], Y[edge]]), seen, corrected, camera, reach)
    return ray


def _occluded_cells(src, sig, occluded, slices):
    """Cells under a face that hid the waterline behind it (diagnostics["occluded_cells"],
    a mask on the output grid): their height comes from the frames where they were still
    seen, so it is known to within a level step (uniform over it: step / sqrt(12))."""
    if not isinstance(occluded, np.ndarray) or occluded.shape != src.shape or not occluded.any():
        return src, sig
    step = level_step(slices)
    on = occluded & (src >= 0)
    src = np.where(on, OCCLUDED, src).astype(np.int8)
    sig = np.where(on, np.maximum(np.nan_to_num(sig), step / math.sqrt(12.0)), sig)
    return src, sig
