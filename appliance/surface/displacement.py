"""Liquid displacement: nominal frame levels -> true levels, from our own slices.

Shared definition (sim/physics.py simulates exactly this): the nominal level
assumes the part fully submerged; as it emerges the ink drops,
    L_true = L_nominal - V_emerged(L_true) / A_tank,
    V_emerged(L) = integral over the base of max(height - L, 0) = integral_L^top area(z) dz.
area(z) is what each waterline encloses (holes run clockwise and subtract), so
the slices measure V_emerged themselves: the trapezoid rule between frames,
and above the highest frame that shows the part a cap whose area shrinks
linearly to zero (a paraboloid's does), its height taken from how fast the
area grows between the two highest frames, never more than the gap to the
frame above (where the part was not yet visible). The levels the areas belong
to are the unknown true ones, so the whole set is solved by fixed point: the
iteration contracts because the emerged area is smaller than the tank's.
"""

from __future__ import annotations

import numpy as np

from ..errors import SettingError
from .lattice import fill_nearest


def emerged_volumes(levels, areas, gap_above=None):
    """V_emerged at each level (levels highest first, areas in mm^2) -> mm^3."""
    levels = np.asarray(levels, float)
    areas = np.asarray(areas, float)
    V = np.zeros(levels.size)
    vis = np.flatnonzero(areas > 0)
    if vis.size == 0:
        return V
    f = vis[0]
    V[f] = cap_volume(levels, areas, f, gap_above)
    for k in range(f + 1, levels.size):
        V[k] = V[k - 1] + 0.5 * (areas[k] + areas[k - 1]) * (levels[k - 1] - levels[k])
    return V


def cap_volume(levels, areas, f, gap_above=None):
    """Volume above the highest frame f that shows the part."""
    A0 = areas[f]
    limit = levels[f - 1] - levels[f] if f > 0 else gap_above
    if f + 1 < levels.size and levels[f] > levels[f + 1]:
        growth = (areas[f + 1] - A0) / (levels[f] - levels[f + 1])  # mm^2 per mm of depth
        hc = A0 / growth if growth > 0 else np.inf
    else:
        hc = np.inf
    if limit is None:
        limit = (levels[f] - levels[f + 1]) if f + 1 < levels.size else 0.0
    hc = min(hc, limit)
    return 0.5 * A0 * hc


def true_levels(nominal, areas, tank_area_mm2, iterations=100, tol=1e-10):
    """Solve L_true = L_nominal - V_emerged(L_true) / A_tank for all frames at once."""
    if not (tank_area_mm2 and tank_area_mm2 > 0):
        raise SettingError("tank.inner_area_mm2", f"must be a positive area, got {tank_area_mm2!r}")
    nominal = np.asarray(nominal, float)
    areas = np.asarray(areas, float)
    if areas.max(initial=0.0) >= tank_area_mm2:
        raise SettingError(
            "tank.inner_area_mm2",
            f"{tank_area_mm2:g} mm^2 is smaller than the part's waterline area ({areas.max():.0f} mm^2)",
        )
    return _solve_levels(nominal, lambda L: emerged_volumes(L, areas), tank_area_mm2, iterations, tol)


def _solve_levels(nominal, volume, tank_area_mm2, iterations, tol):
    """Fixed point of L = L_nominal - V_emerged(L) / A_tank (contracts: part area < tank's)."""
    nominal = np.asarray(nominal, float)
    L = nominal.copy()
    for _ in range(iterations):
        L_new = nominal - volume(L) / tank_area_mm2
        if np.max(np.abs(L_new - L)) < tol:
            return L_new
        L = L_new
    return L


def levels_from_surface(nominal, z, cell_area_mm2, tank_area_mm2, iterations=100, tol=1e-10, weights=None):
    """True levels from a height map of the part (z, NaN off the part): the emerged
    volume integrated over the map itself, V(L) = sum max(z - L, 0) * cell area.

    The waterlines' own areas undercount it wherever the ink climbs the part (a
    meniscus: the contact line encloses the level curve L + h, not L), so once a
    fit exists its volume is the better measure.

    `weights`: each node's share of its cell on the part (lattice.area_weights from the
    outline); nodes just off the fit then take their nearest fitted height. Without them
    the trapezoid rule over the nodes on the part."""
    z = np.asarray(z, float)
    on = np.isfinite(z)
    if weights is not None and on.any():
        w = np.asarray(weights, float)
        z = fill_nearest(z)
        on = w > 0
    else:
        # trapezoid rule: a node weighs the quarter of each neighbouring cell that lies
        # wholly on the part (an edge node half, a corner a quarter)
        cell = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
        w = np.zeros(z.shape)
        for dj in (0, 1):
            for di in (0, 1):
                w[dj : dj + cell.shape[0], di : di + cell.shape[1]] += 0.25 * cell
    order = np.argsort(-np.where(on, z, -np.inf).ravel())
    keep = on.ravel()[order] & (w.ravel()[order] > 0)
    zz = z.ravel()[order][keep]
    ww = w.ravel()[order][keep]
    if zz.size == 0:
        return np.asarray(nominal, float)
    wz = np.cumsum(ww * zz)  # over the k highest nodes
    wsum = np.cumsum(ww)

    def volume(L):
        k = np.asarray(np.searchsorted(-zz, -L, side="left"))  # nodes higher than L
        i = np.maximum(k - 1, 0)
        return cell_area_mm2 * np.where(k > 0, wz[i] - wsum[i] * L, 0.0)

    return _solve_levels(nominal, volume, tank_area_mm2, iterations, tol)


def correct_slices(slices, tank_area_mm2, levels=None):
    """Slices (highest first) with their levels and point heights moved to the true levels
    (solved from the waterlines' areas, or given)."""
    nominal = [s.level for s in slices]
    areas = [max(s.area(), 0.0) for s in slices]
    L = true_levels(nominal, areas, tank_area_mm2) if levels is None else np.asarray(levels, float)
    out = [s.at_level(lv) for s, lv in zip(slices, L)]
    info = {
        "tank_area_mm2": float(tank_area_mm2),
        "nominal_mm": list(map(float, nominal)),
        "true_mm": list(map(float, L)),
        "max_drop_mm": float(np.max(np.asarray(nominal) - L)),
    }
    return out, info
