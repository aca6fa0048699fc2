"""Occluded walls: parts whose steep faces hide their own waterlines from the camera.

A wall steeper than the camera's ray (85 deg at 40 mm from the camera's foot, 300 mm
up: the ray leans 7.6 deg) is seen from above by its rim, not by its waterline. Read as
a waterline, the rim's silhouette claims the part stands where it only hides the ink.
This bench renders the two parts built for it (appliance/sim/surfaces.py) and prints,
per part and effects preset, our fit's Ea, the 99th percentile and the maximum of the
error over the interior cells (those whose neighbours are all on the part too), and the
share of cells the reconstruction marked as under an occluding face.

    nice -n 10 .venv/bin/python benches/occlusion.py --keep /tmp/occl-cache
    nice -n 10 .venv/bin/python benches/occlusion.py --effects clean --parts blade
    nice -n 10 .venv/bin/python benches/occlusion.py --refine-mm 0   # the plan's levels only

Measured (2048 x 1536, 1 mm steps, 50 x 50 grid; before = silhouettes read as waterlines):
    stepped-block clean    Ea 3.15 -> 0.52 mm (p99 3.6, max 6.6)   physics 3.69 -> 1.06
    blade         clean    Ea 1.05 -> 0.17 mm (p99 2.4, max 12.1)  physics 1.04 -> 0.45
With a tilted face that one level curve crosses placed as one plane through it (gridfit.
tilt_crossed_faces; its two pieces had been flat at their bracket middles, a step apart):
    stepped-block clean    Ea 0.517 -> 0.382 mm (p99 3.65, max 6.62)  physics 1.064 -> 1.049
    blade                  unchanged (0.165 clean, 0.454 physics)
What is left: the cells on and beside the 84-85 deg walls (0.19 of the stepped block's 0.38:
a wall the camera does see, 0.09 mm per level, is read right as waterlines, but its nodes'
first exposure comes from raster masks a lattice cell wide, and the thin plate rings beside
the 18 mm jump: 9.0 mm on the 12 mm tier at the foot, 22.0 halfway up), the cells within a
few mm of a wall or rim that are no face node and keep the fit's own tilt, and with the
physics preset the meniscus on the faces' rims.

3 December 2026 (session 12), main df51207 first (stepped-block clean 0.3526 / 2.967 / 6.620,
blade 0.1653 / 2.400 / 12.118: the blade's hidden flank clamped at 6 mm, the level its foot came
out at with the rims put back). With each node held between what the frames saw for sure
(surface/inkbounds.py: out of the ink inside a waterline, ink over it outside one as seen, and
behind a silhouette the ray over the rim), same renders, Ea / interior p99 / max mm:
    stepped-block clean    0.3526 -> 0.2326  (p99 2.967 -> 2.682, max 6.620 -> 4.856)
                  physics  0.9740 -> 0.9702  (p99 5.280 -> 5.180, max 7.621 -> 6.677; 41 holes)
    blade         clean    0.1653 -> 0.0824  (p99 2.400 -> 0.642, max 12.118 -> 1.619)
                  physics  0.4372 -> 0.4269  (p99 5.354 -> 4.256, max 7.282 -> 4.953)
What is left (clean): the stepped block's 85 deg walls facing away from the camera lean 1.4 deg
steeper than its ray, so the ray over the rim bounds them 4-5 mm high halfway down (the column
of cells on the 18 mm jump's far wall; the cells on walls hold 0.165 of the 0.233); nothing the
frames saw tells such a wall from one along the ray (the blade's flank, where that bound is its
height). The blade's 3.6 mm slab came out at once between levels 3 and 4 and lies at the
bracket's middle: 0.1 mm on each of its 1052 cells, 0.067 of its 0.082. With physics the
ceiling carries the ink's largest rise (3.8 mm on a wall) and says little.
Then (036c233) only a node a face hid is held under its ceiling, and a node whose floor is
above its ceiling keeps neither (on harsh sample 4 a 38.6 mm edge node stood at a 17.5 mm
ceiling, 21 mm off: a waterline at a wall's edge moves as far as the stage plays): clean,
same renders, stepped block 0.2905 (p99 2.682, max 6.620), blade 0.0989 (p99 1.376, max
2.400): both targets (0.3, 0.1) still met, by less.
5 December 2026 (session 27, 9b7036c): the exact side decides at a rim put back as at a wall's
foot, and a node seen under a face's silhouette before it came out has no height of its own
(surface/inkbounds.py behind_faces); the same renders, clean, Ea / interior p99 / max mm:
    stepped-block 0.2952 / 3.856 / 7.667 -> 0.2972 / 4.160 / 9.529
    blade         0.0993 / 1.571 / 2.400 -> 0.0983 / 1.446 / 2.400
and tests/test_surface_occlusion.py's small-camera blade 0.1166 -> 0.1202 (0.1348 with the
exact sides alone: its flank, 20 mm high behind the crest, came out with the 3 mm plate).
Behind a rim the frames cannot tell a vertical wall (the strip beyond lies at its floor) from
a flank along the ray (at its ceiling); the fit's side of that, under the ray, leaves material.

6 December 2026 (session 31). The renderer gives each tier its own contact line (the upper
tier's wall no longer lifts the ink over the lower tier's face; single-tier parts render as
before), and at a sharp edge the meniscus solve keeps a face's own rise (surface/sharp_edges.py).
Physics preset, Ea / interior p99 / max mm: the stepped block rendered again, 045a73c 0.8110 /
5.533 / 11.39 on the old render, 0.8217 / 5.530 / 11.82 on the new, ab9b9cf 0.8182 / 5.514 /
8.423; the blade (the same render) 0.3553 / 4.492 / 7.200 -> 0.3327 / 5.169 / 7.202 (its p99
worse: the hidden flank's cells). Clean: no meniscus, so unchanged.
Then (44e46e9) a ceiling that is the ray over a rim holds every node, not only those marked
hidden; the same renders, a3ee1e3 -> 44e46e9: clean stepped block 0.2972 / 4.160 / 9.529 ->
0.2882 / 4.119 / 5.667, blade 0.0983 / 1.446 / 2.400 -> 0.0968 / 1.402 / 2.400; physics
stepped block 0.8182 -> 0.8178, blade 0.3327 / 5.169 -> 0.3309 / 4.381.
6 December 2026 (session 32): at a sharp edge a side is level where the fit or the
first-exposure heights are (surface/sharp_edges.py); the same renders, 926816a -> this, physics:
stepped block 0.8178 / 5.514 / 8.423 -> 0.7194 / 5.386 / 8.561, blade 0.3309 / 4.381 / 7.202 ->
0.3333 / 4.872 / 7.203. Clean: no meniscus, so unchanged (0.2882, 0.0968).
6 December 2026 (session 33): the bench scans as the daemon does. Until now it rendered one frame
per millimetre from the first level that showed the part, so a face that came out at once kept its
whole 1 mm bracket; the daemon starts from an empty frame above the top and bisects such steps to
0.1 mm (daemon/runner.py, here sim/scanrender.refine_scan; the stepped block takes 47 frames, the
blade 28-30). Main e986be5, fresh renders of both kinds, Ea / interior p99 / max mm (holes):
    stepped-block clean    1 mm plan 0.2882 / 4.083 / 5.667      as the daemon 0.1603 / 3.954 / 4.841
                  physics  0.7146 / 5.363 / 6.613 (97 holes)     0.4781 / 5.518 / 6.851 (63 holes)
    blade         clean    0.0968 / 1.139 / 2.400                0.0230 / 0.420 / 1.640
                  physics  0.3335 / 4.350 / 7.203 (3 holes)      0.1934 / 3.668 / 4.565 (0 holes)
Both targets (0.3, 0.1) hold clean; with the meniscus neither does. On the physics blade the hidden
flank's occluded and wall cells hold 39 % of the error; the rest is the meniscus (its clean render
is 0.023): the crest's gentle side and the slab beyond the flank's foot +0.1..0.9 mm, and the 4 mm
strip of slab between the far end's taper and the outline, 0.2..0.8 mm high, rising to the edge.
The holes are cells of the footprint on the 85 deg outer walls' foot, outside the top's outline.
Then, in the rim band where the plain solve is level, the lower of the level and the tied meniscus
solves (surface/contact_lines.py; the tie had set the runaway off elsewhere in the band), the
same renders, physics: stepped block 0.4781 / 5.518 / 6.851 -> 0.4644 / 5.505 / 6.857 (64 holes),
blade 0.1934 / 3.668 / 4.565 -> 0.1871 / 3.666 / 4.565. Clean: no meniscus, so unchanged.
6 December 2026 (session 34): near a wall inside the part the meniscus solve reads the top's slope
within 30 % + 0.1 of the fit's (surface/sharp_edges.slope_range_near_walls; benches/meniscus.py
says why), the same renders, physics: stepped block 0.4644 / 5.505 / 6.857 (64 holes) -> 0.4436 /
5.278 / 8.643 (62 holes), blade 0.1871 / 3.666 / 4.565 -> 0.1805 / 3.719 / 4.634. Clean: no
meniscus, so unchanged. With the meniscus both targets (0.3, 0.1) are still missed.
6 December 2026 (session 35): the ray over a rim bounds a node the frames saw hidden behind it
without the ink's largest climb added (3.8 mm for this ink; surface/inkbounds.py, benches/
meniscus.py says why), the same renders, physics: stepped block 0.4436 / 5.278 / 8.643 (62 holes)
-> 0.4030 / 2.880 / 8.643 (62 holes), blade 0.1805 / 3.719 / 4.634 -> 0.1552 / 3.277 / 4.634.
The blade's occluded cells went +2.79 -> +0.69 mm on average (mean |error| 2.83 -> 1.53); what
is left is its gentle faces (interpolated cells +0.09 mm, 58 % of the error). The stepped block's
grid is 0.7-0.8 mm narrower a side than the clean scan's (its lowest frame at -5.0 mm, true
level), and its outermost ring of cells falls on the 85 deg walls, 3.4-5.0 mm high there, which
we place 1.5-3.7 mm higher: about half its Ea. Clean: no meniscus, so unchanged. With the
meniscus both targets (0.3, 0.1) are still missed.
6 December 2026 (session 36): frames whose ink the displacement took below the base top are no
waterlines (surface/corrections.above_base; the stepped block's last four, nominal 4..1 mm, were
at -0.8..-5.0), the same renders, physics: stepped block 0.4030 / 2.880 / 8.643 (62 holes) ->
0.3356 / 3.403 / 7.869 (40 holes), blade 0.1552 / 3.277 / 4.634 -> 0.1488 / 2.845 / 4.439.
Clean: no displacement, so unchanged. The bench now says how much of the part lies beyond the
map's grid, where no cell is and no error is counted: the stepped block's (physics) 137.5 mm², a
strip 0.2-0.55 mm wide along its 85 deg walls' foot, outside the rims put back; 0 for the rest.

6 December 2026 (session 37): the renderer now lets the ink fall away from a camera fixed to the
tank. New renders, physics, Ea / p99 / max:
    before (76a8477; the sphere commissioned 2.954 mm / 2.49 deg, the fall read as if at rest)
        stepped block 0.3713 / 3.399 / 7.748 (45 holes), blade 0.1726 / 3.040 / 4.571 (13 holes)
    frames seen from H + d once the fall is known (9040ab7), the same model
        stepped block 0.3827 / 3.545 / 7.740 (54 holes), blade 0.1598 / 1.843 / 4.480 (0 holes)
    the sphere commissioned from H + d too (8a2b68c): 2.704 mm / 0.04 deg
        stepped block 0.3037 / 2.422 / 6.706 (50 holes), blade 0.1688 / 3.944 / 4.339
    nodes under a frame's ink held below its flat surface (98630f8)
        stepped block 0.3023 / 2.422 / 6.706 (50 holes), blade 0.1291 / 1.672 / 4.339 (0 holes)
    the lowest frame's second look (553ada4): stepped block 0.2990 / 2.518 / 6.700 (50 holes)

7 December 2026 (session 38), the same renders. The 50 holes were nodes inside the true outline
on the grid's edge rows (the rims put back reach to mid-wall on the hidden 85 deg walls), and a
cell with a NaN corner is the base to the CAM: `--mill` (the finishing program milled against
the true part, benches/uncertainty.py) found a 7.593 mm gouge at (77.0, 11.2), p99 3.346 mm.
Nodes within half a cell beyond the lowest frame's outline now hold the part's edge
(surface/edges.py): stepped block 0.3842 / 2.518 / 6.700 (1 hole; 165 mm² beyond the map), the
gouge p99 2.821 mm, the deepest 6.592 mm at (46.6, 61.4), where one cell spans the 18 mm tier's
corner. The edge rows now count in Ea, 0.176 mm of it: on the three hidden walls they stand
2.5-3.7 mm over mid-wall, on the side that leaves material (marked wall, uncertain by at least 1.5-2.8 mm). Blade
unchanged, 0.1291 (gouge 3.880 mm on its hidden flank, p99 0.713).

7 December 2026 (session 39), the same renders: a hidden node is held under every frame's ray
over its rim, the highest of them (surface/rimrays.py), where it was held between the two frames
it was first hidden in, or under the level that first showed ink plus the ink's whole climb.
    stepped block 0.3842 / 2.518 / 6.700 -> 0.3719 / 2.390 / 3.369 (1 hole); milled: gouge 6.592
        -> 6.619 mm at (46.6, 61.4), p99 2.821 -> 2.821, most material left 7.958 mm
    blade 0.1291 / 1.672 / 4.339 -> 0.1175 / 1.447 / 4.282; milled: gouge 3.880 -> 3.854 mm at
        (73.4, 30.0), p99 0.713 -> 0.837, most material left 5.525 -> 4.199 mm
The blade's cells more than 0.5 mm under the true part: 22 -> 23; its hidden flank stands nearer
the truth, yet the milled gouge's p99 rises. Every 0.2 mm stock cell cut 0.3 mm deeper than before
(738 of them, none shallower) lies 0.5-3 mm on the gentle side of the crest line: a 1.7 mm cell
that spans the crest now falls to its flank node, lower and truer than before, and the ball
follows that slope into the sharp crest. Only a finer map holds such a crest. The lowest of the
frames' rays instead gave 0.1197, with 40 cells more than 0.5 mm under the part. Both targets
(0.3, 0.1) are still missed.

7 December 2026 (session 40), fresh renders on another machine: main 77f42c0 gives stepped block
0.4149 / 2.516 / 3.696 (1 hole), blade 0.1162 / 1.445 / 4.283 (session 39's renders: 0.3719,
0.1175; the stepped block moves 0.04 mm between renders of the same seed). A face that came out
at once beside a rim put back is bracketed where the camera saw ink over it, 0.25 mm beyond the
silhouette as seen (surface/flatfaces.py; it had to lie 3 lattice spacings from the rim put
back): stepped block 0.4043 / 2.463 / 3.670, blade 0.1136 / 1.343 / 4.296. On the blade the slab
2-3 mm past the hidden flank's crest, 1.2-1.9 mm high before, now mostly within 0.1; what is left
of the blade's error: the band within 4 mm of the crest 0.052 of its Ea (the hidden flank and
the strip beyond its foot held under the ray, 2-4 mm past the crest +0.7 mm on average), the
tapered ends 0.028 (the slab beyond the far taper 0.6-1.3 mm high: within 1.7 mm of its own
frame's waterline, where the ink still filled the corner, so no bracket), the rest 0.034.
Then such nodes are bracketed too, near their own frame's level curve (not its walls, nor a loop
under 50 mm²; 24b01c1): stepped block 0.4024 / 2.463 / 3.670, blade 0.1030 / 1.247 / 4.296. With
edge_mm one lattice spacing, not two, the blade would be 0.0939 (harsh crater 0.0367 -> 0.0372,
its p99 as this bench counts it 0.194 -> 0.202). Both targets (0.3, 0.1) are still missed.

7 December 2026 (session 41), the same renders. The stepped block's error was mostly its outer
walls' edge rows (within 2 mm of the outline: 0.228 of its 0.402), the x = 91.5 column 12.4-13.8 mm
against a true 6.1: the fit carried the top on past rims put back from silhouettes, where the
frames saw neither the wall nor its foot. Such an edge node now takes the middle between the base
and the ray over the rim (surface/edges.py), and the CAM mills every outline node marked wall no
lower than its highest neighbour inside, so the program still keeps the edge (cam/sampling.py):
    stepped block 0.4024 / 2.463 / 3.670 -> 0.3307 / 2.463 / 3.670; milled against the true part:
        gouge 7.049 mm at (91.0, 85.0) -> 6.232 mm at (46.6, 61.4) (the upper tier's corner), p99
        3.022 -> 2.501, most material left 8.336 -> 8.352 mm
    blade 0.1030 (no edge node under a ray); milled: gouge 4.286 -> 4.288 mm at (83.6, 74.6), p99
        0.941 -> 0.757 (its outline's wall nodes kept), most material left 4.208 both
    second ink stepped block 0.4207 -> 0.3624; the other eleven second-ink parts, all nine harsh
        parts and the seed table's physics scans the same to the digit
The stepped block's edge rows now give 0.157 of its Ea; most of it is the y = 86 row (0.060),
footprint nodes, not edge nodes, that stand 1-6 mm over a true 5.7.

7 December 2026 (session 42), the same renders. The blade's plate beside its tip and beyond its
hidden flank's foot had no bracket (too near the plate's rim or the frame above's waterline) and
no waterline across it, and the fit carried the tip and the flank into it (up to 9.5 mm, clipped
at 4.3-7.9 by the ink's bound over a true 3.6). A node whose fit runs over its ceiling beside a
face that came out in the same frame now takes the face's height (surface/flatfaces.py
beside_faces): blade 0.1030 / 1.247 / 4.296 -> 0.0914 / 1.056 / 2.847, within its target; milled
gouge 4.288 -> 4.280 mm, p99 0.757 -> 0.759. Stepped block 0.3307 -> 0.3306. Clean preset (fresh
renders): blade 0.0236, stepped block 0.1466 (0.0245, 0.1477 before).

7 December 2026 (session 42), the renderer fixed: where a pixel's ray grazes a wall leaning with
it (the stepped block's 85 deg walls facing away), Newton's search for where the ray meets the
tier cycled and ended off the top but inside the footprint, and the pixel was drawn as part. The
hidden rims' silhouettes came out 2 px (0.157 mm) beyond where the rays graze them, at every level
(visible waterlines: 0.000 mm off), so the rays over them read 1-2 mm too high. Such a ray is now
sought by sampling it (sim/render.py). Only the stepped block's frames change (21432 pixels over
six levels; the blade 15, every other part 0). Fresh stepped-block renders, blade kept:
    stepped block clean    0.1466 / 4.000 / 4.838 -> 0.1348 / 2.224 / 5.505 (29 holes: the map's
        outline now stops at the rims, and the 85 deg walls' foot cells, 0.75 mm high, are off it)
    stepped block physics  0.3306 / 2.463 / 3.670 -> 0.2486 / 3.434 / 4.103, within its target;
        the part beyond the map 160.5 -> 323.1 mm² (the walls' strip between rim and foot)
    second ink (benches/meniscus.py), stepped block 0.3621 -> 0.2912
On these renders the edge nodes' ray rule of session 41 costs the physics scan: with the top
carried on instead (its rule before) 0.1960, clean 0.1505. The rule stays: the frames cannot tell a
wall along the ray (truth near the top) from a vertical one (truth at the base), and the middle of
the two is what they allow.

7 December 2026 (session 43), the renderer again: Newton, started at the liquid, could meet a ray
grazing a battered wall where it comes out of the wall, under the top the camera sees, and a
strip along the y = 86 rim was drawn as ink over rays 1.1-1.2 mm deep in the part. Such a meeting
is now handed to the sampler, and a ray none of whose samples is in the part gets a search for
its closest approach (a rim corner it clips). Only the stepped block's frames change (848
pixels over six levels). Fresh stepped-block renders, blade kept:
    stepped block clean    0.1348 / 2.224 / 5.505, 29 holes -> 0.1415 / 3.808 / 3.941, no holes;
        milled: gouge 6.297 mm at (84.8, 22.2), p99 2.192
    stepped block physics  0.2486 / 3.434 / 4.103 -> 0.2154 / 3.619 / 3.798, within its target;
        milled: gouge 6.461 -> 6.283 mm, same place (the upper tier's hidden corner, marked
        occluded +-2.53), p99 2.513 -> 2.481
The held-under-a-depression bound for faces that came out at once (same session) changes
nothing here: the first ink commissions to 0.04 deg. The closest-approach search then kept one
point a step (review mend; 40 pixels of the stepped block change over six levels). Fresh
stepped-block renders again: clean 0.1371 / 3.809 / 3.942, milled gouge 6.173 at (85.0, 22.0),
p99 2.167; physics 0.2157 / 3.621 / 3.799, milled gouge 6.302 at (84.8, 22.2), p99 2.477.

physics: the camera block in each scan.json is our calibration from rendered
chessboards and the meniscus model comes from a rendered sphere scan (as in
benches/seed_table.py); the scans and the calibration are kept in --keep and reused.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from scipy import ndimage

from appliance import process as proc
from appliance.sim import surfaces
from appliance.sim.levels import ink_margins, sculpture_levels
from appliance.sim.render import effects_preset
from appliance.sim.scanrender import refine_scan, render_scan
from appliance.vision.refine import RESOLUTION_MM

sys.path.insert(0, str(Path(__file__).resolve().parent))
from outline import outside_map, spurious
from seed_table import calibrated_camera, calibrated_meniscus, use_camera

PARTS = ("stepped-block", "blade")


def tail(surface, hm):
    """Ea over all cells, p99 and max over the interior cells, mm."""
    X, Y = hm.grid()
    on = surface.inside(X, Y)
    err = np.abs(surface.height(X, Y) - hm.z)
    ok = on & np.isfinite(err)
    interior = ndimage.binary_erosion(on, np.ones((3, 3)), border_value=0) & ok
    e = err[interior] if interior.any() else err[ok]
    return (
        float(err[ok].mean()),
        float(np.percentile(e, 99)),
        float(e.max()),
        int((on & ~np.isfinite(hm.z)).sum()),
    )


def calibration(keep: Path, effects):
    cam_file, men_file = keep / "camera.json", keep / "meniscus.json"
    if not cam_file.is_file():
        cam_file.write_text(json.dumps(calibrated_camera(keep)))
    camera = json.loads(cam_file.read_text())
    if not men_file.is_file():
        calibrated_meniscus(keep, effects, camera)
    return camera, men_file


def daemon_levels(surface, effects, step):
    """The plan the daemon's runner follows: from the first empty frame above the top (higher by
    the ink's stand over a flat top it has left) down until the top is out by the rise on a wall."""
    below, above = ink_margins(effects_preset(effects))
    return sculpture_levels(surface, step, below, True, above)


def run(part, effects, keep: Path, grid_n, step, refine_mm, milled=False):
    surface = surfaces.get(part)
    folder = keep / (f"{part}-{effects}-{step:g}" + ("-refined" if refine_mm > 0 else "-plan"))
    t0 = time.perf_counter()
    camera = meniscus = None
    if effects == "physics":
        camera, meniscus = calibration(keep, effects)
    if not (folder / "scan.json").is_file():
        render_scan(
            surface, folder, levels=daemon_levels(surface, effects, step), effects=effects, seed=1, workers=2
        )
        if camera:
            use_camera(folder, camera)
        if refine_mm > 0:
            refine_scan(surface, folder, refine_mm, effects=effects, seed=1, workers=2)
    t1 = time.perf_counter()
    job = proc.process(folder, grid_n=grid_n, truth=surface, meniscus=meniscus if meniscus else False)
    t2 = time.perf_counter()
    ea, p99, mx, holes = tail(surface, job.heightmap)
    beyond = outside_map(surface, job.heightmap)
    extra, tallest = spurious(surface, job.heightmap)
    occ = job.diagnostics.get("fit", {}).get("occluded_nodes", 0)
    frames = len(json.loads((folder / "scan.json").read_text())["frames"])
    print(
        f"  {part:<14} {effects:<8} Ea {ea:7.4f}  p99 {p99:7.3f}  max {mx:7.3f} mm  holes {holes:3d}  "
        f"beyond the map {beyond:5.1f} mm²  "
        f"beyond the part {extra:5.1f} mm² (up to {tallest:.2f} mm)  occluded nodes {occ:5d}  frames {frames:3d}  (render {t1 - t0:.0f} s, process {t2 - t1:.0f} s)",
        flush=True,
    )
    if milled:
        from uncertainty import mill

        rep, gouge_p99, _, _, said, _ = mill(surface, job, 0.2)
        print(
            f"  {'':<14} {'':<8} milled against the true part: gouge {rep.gouge:.3f} mm at "
            f"({rep.gouge_at[0]:.1f}, {rep.gouge_at[1]:.1f}) [{said}], p99 {gouge_p99:.3f} mm",
            flush=True,
        )
    return ea


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--effects", default="clean,physics")
    ap.add_argument("--parts", default=",".join(PARTS))
    ap.add_argument("--grid", type=int, default=50, help="output grid cells a side")
    ap.add_argument("--step", type=float, default=1.0, help="level step, mm")
    ap.add_argument(
        "--refine-mm",
        type=float,
        default=RESOLUTION_MM,
        help="bisect the steps in which a face came out at once to this, as the runner does (0: the plan's levels only)",
    )
    ap.add_argument("--keep", help="folder to keep rendered scans and calibrations in (and reuse)")
    ap.add_argument(
        "--mill",
        action="store_true",
        help="mill the finishing program against the true part (benches/uncertainty.py; minutes a part)",
    )
    a = ap.parse_args()
    print(
        f"occluded walls, scanned as the daemon does ({a.step:g} mm steps from an empty frame above the top, "
        f"refined to {a.refine_mm:g} mm), {a.grid} x {a.grid} grid: errors of our fit against the true part"
    )
    with tempfile.TemporaryDirectory(prefix="occlusion-") as tmp:
        keep = Path(a.keep or tmp)
        keep.mkdir(parents=True, exist_ok=True)
        for effects in a.effects.split(","):
            for part in a.parts.split(","):
                run(part, effects, keep, a.grid, a.step, a.refine_mm, a.mill)


if __name__ == "__main__":
    main()
