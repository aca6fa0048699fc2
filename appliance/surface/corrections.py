"""The waterlines put right before each fit: wall edges where the walls are, true levels.

Before the first fit nothing but the waterlines is known: walls are found, their edges put
back with heights bracketed by the frames, and the ink's true levels come from the areas
the waterlines enclose (when the tank's area is given). From the second pass on the fit
before gives each edge's height (rim_height) and the emerged volume, and so better levels.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .lattice import area_weights, bilinear, fill_nearest
from .perspective import mark_walls, unproject_rims
from .silhouettes import mark_silhouettes
from .slices import shows_waterline


def corrected_levels(seen, opt, diag, lat=None, z=None, levels=None):
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
        edge_height = rim_height(lat, z) if z is not None else None
        slices = unproject_rims(slices, opt.perspective, opt.wall_tol_mm, edge_height, max(rise, 0.0), rng)
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


def above_base(seen, slices, diag):
    """(seen, slices) without the frames whose true level is at or below the base top.

    A frame's nominal level does not tell: a part that displaces much ink takes the ink
    below the base top before the stage reaches level 0 (sample 2's last six frames,
    nominal 9..4 mm, were at -1.7..-10.7 mm). Such a frame shows the part's foot or, on a
    box, the base's outline: not a level curve at its level. Read as one, it put off the
    levels solved from the fit's volume (sample 2 under the first ink: its frames at 25 mm
    came out 0.012 mm low, and 0.000 without them)."""
    keep = [i for i, s in enumerate(slices) if shows_waterline(s.level)]
    if len(keep) == len(slices) or len(keep) < 2:
        return seen, slices
    disp = diag.get("displacement")
    if disp is not None:
        for key in ("nominal_mm", "true_mm"):
            disp[key] = [disp[key][i] for i in keep]
        disp["max_drop_mm"] = max(n - t for n, t in zip(disp["nominal_mm"], disp["true_mm"]))
    below = [s.level for s in slices if not shows_waterline(s.level)]
    diag.setdefault("notes", []).append(
        f"{len(below)} frame(s) whose ink had dropped to or below the base top "
        f"({max(below):.2f} mm and lower) not used: they show the part's foot, not a waterline"
    )
    return [seen[i] for i in keep], [slices[i] for i in keep]


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


RIM_INSET = 2  # lattice nodes: nearer its outline than this the fit is extrapolating


def rim_height(lat, z):
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
