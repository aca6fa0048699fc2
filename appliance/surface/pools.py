"""Pockets that held ink: a hole in the part whose far shore recedes as the ink drops.

As the base rises the ink drains off the part wherever it can run down to the tank. A pocket
in the top (a bowl, a mould cavity, a crater inside its ridge) cannot drain: once its rim is
out, the pocket stays full to its spill height S and its floor is never seen. Every frame
below S shows the pool as a hole in the part, and without this module the fit read that hole
as a hole down to the base: the program milled the pocket out to z = 0 (the crater's bowl,
floor at 5 mm, came out 21 mm deep at its worst).

What tells such a pool from a hole the tank's ink reaches: its shore stands above the ink,
S - L at level L, and the part rises towards the camera, so the shore is seen further from
the camera's foot at every lower level. The hole as observed grows as the ink drops, by
2 dL / (H - h) of its area per level step dL (0.7 % a millimetre, 300 mm up). A hole the
tank's ink reaches never grows: its shore is a waterline on a slope, which closes in as the
ink drops, or at the foot of a wall, which stays put (on its near side the wall's raised top
edge moves in: it shrinks a little).

So a hole of the lowest frame whose observed area grows, going down the frames that show it,
by at least GROWTH_SHARE of what a raised shore would, is a held pool. It held ink from the
first frame that shows it enclosed (the level above showed no such hole), so S lies between
those two levels. The cells inside the shore, put back from where the lowest frame saw it
(and outside any island the pool surrounds), are set to the top of that bracket plus what a
meniscus can cling: above any floor under the pool, so the program leaves the pocket uncut
rather than guess. They are marked `held`, uncertain by a floor anywhere between the base
and S, and the report says where the pool was.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..vision.types import signed_area
from .confidence import regions
from .heightmap import HeightMap
from .lattice import Lattice, inside_loops
from .perspective import Perspective
from .uncertainty import HELD

GROWTH_SHARE = 0.5  # of the growth a shore standing above the ink would show, the least that counts
MIN_DROP_MM = 2.0  # a hole followed over less than this drop of the ink says nothing either way
MIN_AREA_MM2 = 4.0  # smaller holes are left to the base plane's rules


@dataclass(frozen=True)
class HeldPool:
    shore: np.ndarray  # (N, 2) mm: the pool's edge on the part, put back where it stands
    bracket: tuple  # (lo, hi) mm: the pool's surface lies between these levels
    area_mm2: float  # inside the shore
    islands: tuple = ()  # (N, 2) mm outlines of what stands out of the pool, put back likewise

    @property
    def centre(self):
        return tuple(float(v) for v in self.shore.mean(axis=0))


def held_pools(frames: list, camera: Perspective | None) -> list[HeldPool]:
    """The held pools among the holes of the lowest frame. `frames`: (level, loops as
    observed) top first, the levels the ink's true ones where known; camera: where the
    camera stands (without it no shore can be told from a waterline: none)."""
    if camera is None:
        return []
    out = []
    for low, loop, inside in _low_holes(frames):
        track = _follow_up(frames, low, inside)
        if _grows_like_a_raised_shore(track, camera.height_mm):
            out.append(_pool(track, frames, camera, loop))
    return out


def pools_suspected(frames: list, camera: Perspective | None) -> bool:
    """Whether a pocket may have held ink, as a read that confirms part by the lower frames
    alone shows it: a hole of the lowest frame that a frame less than MIN_DROP_MM above has
    not got round the same point (that read cuts a receding shore away, and a pool's hole
    goes with it), or has smaller. Such a scan is read again with raised shores kept
    (waterlines.py); a hole the tank's ink reaches is never smaller above."""
    if camera is None:
        return False
    return any(_shrinks_above(frames, low, inside, camera.height_mm) for low, _, inside in _low_holes(frames))


def _shrinks_above(frames, low, inside, camera_height_mm) -> bool:
    track = _follow_up(frames, low, inside)
    _, level_low, area_low = track[0]
    for _, level, area in track[1:]:
        if level - level_low > MIN_DROP_MM:
            return False
        if area < area_low * (1.0 - GROWTH_SHARE * 2.0 * (level - level_low) / camera_height_mm):
            return True
    above = track[-1][0] - 1  # the hole is gone here: suspect if the part still shows, near by
    return above >= 0 and len(frames[above][1]) > 0 and frames[above][0] - level_low <= MIN_DROP_MM


def _low_holes(frames):
    """(frame index, hole loop, a point inside it) for the lowest frame's holes."""
    shown = [k for k, (_, loops) in enumerate(frames) if len(loops)]
    if len(shown) < 2:
        return
    low = shown[-1]
    for loop in frames[low][1]:
        if -signed_area(loop) < MIN_AREA_MM2:  # outer loops (counter-clockwise) and specks
            continue
        inside = _point_inside(loop)
        if inside is not None:
            yield low, loop, inside


def _point_inside(loop, cell_mm=0.25):
    """The point of the hole `loop` furthest from its shore (on a cell_mm raster): inside it
    whatever its shape, a crescent's too. None for a hole under a cell across."""
    lo = loop.min(axis=0) - cell_mm
    px = np.round((loop - lo) / cell_mm * 16).astype(np.int32).reshape(-1, 1, 2)
    w, h = (np.ceil((loop.max(axis=0) - lo) / cell_mm) + 2).astype(int)
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [px], 1, shift=4)
    depth = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
    j, i = np.unravel_index(int(np.argmax(depth)), depth.shape)
    return lo + cell_mm * np.array([i, j], float) if depth[j, i] > 1 else None


def _follow_up(frames, low, point):
    """[(frame index, level, area)] of the holes round `point`, from the lowest frame up while
    each frame has one."""
    track = []
    for k in range(low, -1, -1):
        hole = _hole_round(frames[k][1], point)
        if hole is None:
            break
        track.append((k, frames[k][0], -signed_area(hole)))
    return track


def _hole_round(loops, point):
    for loop in loops:
        if (
            signed_area(loop) < 0
            and cv2.pointPolygonTest(loop.astype(np.float32), (float(point[0]), float(point[1])), False) > 0
        ):
            return loop
    return None


def _grows_like_a_raised_shore(track, camera_height_mm) -> bool:
    """The hole's observed area grows as the ink drops (d ln A / dL against -2 / H)."""
    if len(track) < 3:
        return False
    L = np.array([t[1] for t in track])
    if L.max() - L.min() < MIN_DROP_MM:
        return False
    slope = np.polyfit(L, np.log([t[2] for t in track]), 1)[0]  # per mm of level, < 0: grows going down
    return slope < -GROWTH_SHARE * 2.0 / camera_height_mm


def _pool(track, frames, camera, loop) -> HeldPool:
    k_low, level_low, _ = track[0]
    k_high, level_high, _ = track[-1]
    above = [frames[k][0] for k in range(k_high)]  # the frames above the first enclosed one
    hi = min(above) if above else level_high + 1.0
    lo = level_high
    poly = loop.astype(np.float32)
    islands = [
        i
        for i in frames[k_low][1]
        if signed_area(i) > 0
        and all(cv2.pointPolygonTest(poly, (float(u), float(v)), False) > 0 for u, v in i[::8])
    ]

    # the lowest frame saw the shore S - level_low above the ink: put back, S the bracket's middle
    def put_back(outline):
        return camera.true_xy(np.asarray(outline, float), np.full(len(outline), 0.5 * (lo + hi) - level_low))

    shore = put_back(loop)
    return HeldPool(
        shore, (float(lo), float(hi)), float(-signed_area(shore)), tuple(put_back(i) for i in islands)
    )


def cover_held_pools(
    hm: HeightMap, pools: list[HeldPool], rise_mm: float = 0.0
) -> tuple[HeightMap, list[str]]:
    """hm with the cells inside each pool's shore at the highest its surface can have stood,
    marked HELD; and a sentence per pool for the report.

    That height is the top of its bracket, the level above the first frame that showed the
    pool enclosed, plus the most the ink can cling to a rim (`rise_mm`, the meniscus' rise
    on a wall): everything under the pool is lower, so the program cuts none of it. The
    part's own heights round the shore are no surer bound: a thin rim's cells mix in its
    wall (a bowl's came out 2-3 mm low there, and a pool held at them 1 mm into its side)."""
    if not pools:
        return hm, []
    grid = Lattice(hm.x, hm.y)
    z = hm.z.copy()
    sigma = None if hm.sigma is None else hm.sigma.copy()
    source = None if hm.source is None else hm.source.copy()
    notes = []
    for pool in pools:
        inside = inside_loops(grid, [pool.shore, *pool.islands])  # even-odd: islands stay out
        if not inside.any():
            continue
        surface = pool.bracket[1] + rise_mm
        z[inside] = surface
        if sigma is not None:
            sigma[inside] = surface / np.sqrt(12.0)  # a floor anywhere between the base and the surface
        if source is not None:
            source[inside] = HELD
        x, y = pool.centre
        notes.append(
            f"a pocket held ink (around x {x:.1f}, y {y:.1f} mm, {pool.area_mm2:.0f} mm²): its floor was "
            f"never seen, so the map holds it at {surface:.2f} mm, the highest the ink in it can have "
            "stood, and the program leaves it uncut. Fill it flush or drill a drain hole at its lowest "
            "point to scan it"
        )
    return HeightMap(hm.x, hm.y, z, sigma, source), notes


def held_notes(hm):
    """A G-code header line per pocket that held ink: where, and the height it is left at."""
    if hm.source is None:
        return []
    return [
        f"pocket that held ink: X {r.xmin:.1f}..{r.xmax:.1f} Y {r.ymin:.1f}..{r.ymax:.1f} mm left uncut "
        f"at Z{r.z_mm:.2f}; its floor was not seen"
        for r in regions(hm, hm.source == HELD)
    ]
