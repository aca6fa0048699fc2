"""CAM benchmarks: drop-cutter speed and agreement against OpenCAMLib, and the
issue-5 acceptance table (gouge and scallop per sample and cutter, ours vs the
dissertation's format).

    .venv/bin/python benches/cam.py            # everything (~10-20 min on 2 busy cores)
    .venv/bin/python benches/cam.py --quick    # a slice of each (~2 min)
    .venv/bin/python benches/cam.py --only dropcutter|acceptance|fullmap|dialects|finishing|rim

`--only finishing` times issue 20's case (sample 1 from a 0.5 mm map, 6 mm ball,
scallop 0.05 and 0.01) in child processes and runs the same in a `git worktree`
of the commit before issue 20 (--old-ref, default 30fd316) for the ratio.
Measured 2026-12-02 (shared 2-core box, load 15-20), new | 30fd316:
scallop 0.05: 6.9 s CPU, 175 MB, 119 passes | 31.5 s, 426 MB, 120 (4.5x, 2.4x);
scallop 0.01: 20.8 s, 186 MB, 266 passes | 62.8 s, 444 MB, 266 (3.0x, 2.4x).
Targets 5 s and 20 s not yet met: the planner's envelopes of each candidate pass
(~2 s at 0.05) and the opening over the whole map (~1.9 s) are most of what is left.

`--only rim` is issue 20's "the rim is finished": each sample and cutter of the
acceptance table, a program with margin RIM (passes run off the outline by the
cutter's radius less a step; `toolpath --rim`) verified with no edge band: the
uncut share of the reachable area (target <= 1 %) and the maximum scallop
(within 10 % of the request); `--rim-compare` prints the margin-0 default
beside it. Measured 2026-12-02 (RIM): sample1 ball6 0.05: 0.00 % uncut, max
0.0491, gouge 0.0029 (margin 0 left 250 mm^2 of rim unmeasured); sample2 ball6
0.01: 0.00 %, 0.0098, 0.0014; sample3 flat6 0.05: 0.00 %, 0.0715 at the corner
(0, 100) MISS; sample4 bull1r0.25 0.01: 0.00 %, 0.0569 at its edge MISS. RIM is
not the default yet: sample 1 at 0.01 took 58.6 s / 886 MB with it against
14.9 s / 202 MB without (refining the moves that roll over the rim).
2026-12-03, one run, c2565ef | 7ffa848, RIM, sample 1 from 0.5 mm, ball6: 0.05:
8.3 s / 197 MB | 6.5 s / 188 MB; 0.01: 49.4 s / 892 MB | 34.6 s / 494 MB; margin 0
unchanged (the same programs): 4.3 s / 174 MB and 12.3 s / 192 MB. 7ffa848 took the
off-part moves from a fine line of tips instead of refining them point by point
(refinement 17 s -> ~0 at 0.01), but sample4 bull1r0.25 then gouged 0.0051 (0.0047
without): withdrawn; with the planner's envelopes in blocks alone 0.01 is 43.9 s /
494 MB. Still 3x margin 0: the planner crawls over the outline (stepovers of
0.01-0.06 mm for the first passes off the part, which only pivot on its edge), and
its rows for those tiny gaps are the 494 MB. Rim rows: sample1 ball6 0.01 0.0100 OK,
sample2 ball6 0.01 0.0098 OK, sample3 flat6 0.0715 and sample4 bull1r0.25 0.0569
still MISS (the planner's).
2026-12-03, session 10 (loaded box, load ~10): the planner's fine search around a cusp
now stays between the two passes' contacts (off the part every pass pivots on the
outline at the same row, and the rows just inside read as a cusp of slope x row step:
20 passes 0.01-0.06 mm apart, now 3), and the pass ends off the part take their tips
from fine lines, every fine move checked at its midpoint (rimline.py). Sample 1, ball6,
RIM, one run, 3ab8bb7 | now: 0.05: 10.8 s | 8.7 s; 0.01: 59.2 s | 21.7 s (plan 46.8 ->
12.2, refining the rim 10.7 -> 6.4), margin 0 beside it 17.9 s. `--only finishing
--old-ref 3ab8bb7` (RIM rows new only): 0.05: margin 0 5.3 s / 174 MB (old 5.0), RIM
8.0 s / 183 MB = 1.52x; 0.01: margin 0 16.3 s / 197 MB (old 19.5), RIM 32.1 s / 289 MB
= 1.97x / 1.47x (the stage timer above had it 1.2x: the box is noisy; the peak is new,
214 MB before the fine lines, not yet looked into). RIM is not the default: at 0.05 it
would miss the 5 s row that margin 0 only just meets, and at 0.01 the 250 MB one.
`--only rim` with the planner's fix alone (before the fine lines): sample1 ball6 0.0100 /
bull6r1 0.0098 / flat6 0.0495, sample2 ball6 0.0099, all 0.00 % uncut, gouge <= 0.0029
(OK); with the fine lines too: sample4 bull1r0.25 0.0560 MISS as before, gouge 0.0050
(0.0047 without the fine lines: at the 0.005 limit); sample1 ball6 0.0100, 0.00 %, gouge
0.0019 OK (the same as before). The other rows not yet re-run.
Session 11 (keepup), `--only finishing --old-ref 13e7e57`, one run, load ~19: 0.05: 6.3 s /
142 MB | 7.0 s / 174 MB (the same program: the peak from smaller blocks in the drop's edge
contacts and the opening); RIM 8.2 s / 161 MB (1.30x); 0.01: 20.8 s / 201 MB | 20.1 s / 197
MB (1.0x); RIM 27.6 s / 290 MB (1.33x, over the 250 MB row). This dome has no wall, so the
polish's exact facets (the daemon's sphere: 19.3 -> 12.0 s) do not run here; the planner's
envelopes and the opening are still what is left. Then reduce_polyline by pieces between
kept points (the same programs, md5), one run each: 0.01 margin 0 21.8 s / 151 MB (was 201),
RIM 0.01 27.9 s / 151 MB (was 290: the linked runs' whole-run arrays were its peak).
Finishing at branch start of session 8 (e64d41a) vs now, margin 0, one run:
0.05: 4.6 s / 175 MB; 0.01: 14.4 s / 186 MB vs 14.9 s / 202 MB.

Session 12 (2026-12-03, branch s12-rim, loaded box: load 8-13 on 2 cores), `--only
finishing --old-ref none`, new: 0.05: 5.8 s / 163 MB, RIM 7.5 s / 163 MB (1.29x margin 0's
CPU); 0.01: 18.3 s / 203 MB, RIM 22.6 s / 207 MB (1.24x). Profile of RIM at 0.05 (idle box,
cProfile): planner 4.1 s (its opening 1.6, candidate envelopes 1.3, candidate drops 0.7),
the pass ends' fine lines 0.9, the mids' drop 0.4, posting 0.5; at 0.01 the fine lines were
~20 % and the planner's envelopes (their exact sweep between positions ~7 s of 38 profiled)
the rest of what margin 0 does not have. Two changes, the same programs: the fine lines
read on the lines' own lattice (fineline.py: 0.95 -> 0.27 s at 0.05, 4.8 -> 1.45 s at 0.01,
sample 1's RIM program byte for byte the same at 0.05) and posting in one pass per axis
(motion_lines 2x, the same bytes). RIM is still not the default: 7.5 s at 0.05 and 22.6 s
at 0.01 miss the 5 s and 20 s rows (margin 0 misses the first too on this loaded box); what
is left is the planner's own cost, shared with margin 0. Tried and dropped: larger slab
chunks for the fine lines (no gain measurable under the load, +19 MB), a sub-position count
per move instead of per window (more slab margins read: 0.27 -> 0.42 s).
`--only rim` rows with the rim fixes (one program each, verified over the whole part): sample3
flat6 0.05: 0.0643 at (0, 100) MISS -> 0.0485 OK, gouge 0.0023, 0.00 % uncut (a flat end's
positions now reach R - d/10 at both pass ends, and its cusps beside the outline are measured
on all fine rows); sample1 flat6 0.05: 0.0486 OK, 0.0023, 0.00 % (was 0.0495); sample4 flat1
0.05: 0.0508 OK, gouge 0.0036 at its corner (55, 55), 0.00 % (not recorded before); sample2
flat6 0.05: 0.0488 OK, 0.0022, 0.00 %. Sample4 bull1r0.25 0.01: 0.0572 at (55.0, 50.8) on its
far edge MISS, gouge 0.0014 (its 0.48 mm margin stopped the torus where its side is 67
degrees; the verification reaches the 80-degree faces' edge from up to 0.5 mm out) -> a
bull nose also to a tenth of a step short: 0.0102 OK, gouge 0.0036, 0.00 % uncut; sample1
bull6r1 0.01 with it: 0.0098 OK, gouge 0.0028, 0.00 % (was 0.0098, <= 0.0029). Not re-run
this session: sample1-3 ball6 (their programs are the same but for the fine lines' tips,
byte for byte the same on sample1 at 0.05), sample2 bull6r1. sample3 bull6r1 0.01 (not
recorded before), with the tenth: 0.0099 OK, gouge 0.0026, 0.00 % (471 s to plan, loaded). New MISS, row not recorded
before: sample4 ball1 0.01: 0.0371 at (55.0, 50.8), gouge 0.0013, 0.00 % uncut, on the same
far edge as the bull nose's: at 0.48 mm out a 1 mm ball's side is 74 degrees, short of the
80-degree faces; a tenth of a step (side 84 degrees) would reach them, but a ball's tip
races there (11 mm per mm: 0.0055 mm for a 3-decimal dialect's rounding), not yet tried.

Session 13 (2026-12-03, branch s13-rim, load 7-10). `--only rim` sample4 ball1 0.01: 0.0371 at
(55.0, 50.8) MISS -> 0.0109 OK, gouge 0.0037 (was 0.0013), 0.00 % uncut, 324 passes: 0.48 mm
out a 1 mm ball's side at the outline is 74 degrees, short of the 80-degree faces beside it. A
ball now stops a tenth of a step short where a face at the outline is steeper than its side a
step short (zigzag.steep_outline: sample 4 only), else a whole step: a tenth short everywhere
put sample 1's positions off the 0.1 mm lattice's phase (refine() 3 -> 8 levels) and sample 3
ball6 0.01 took 291 passes for 252 (0.0099 OK). Every other rim row's program is byte for byte
ad05d23's (sample 1 RIM and margin 0 at 0.05: md5), so its figures stand; sample3 ball6 0.01, not
recorded before: 0.0097 OK, gouge 0.0014, 0.00 %, 252 passes. Speed: no envelope columns beyond
the footprint (RIM: 58 of ~440, the pass ends off the part), the same programs; one child each,
alternately, new | ad05d23: 0.05: margin 0 5.98, 6.01 s | 6.13, 5.96 s (the same code:
the noise), RIM 6.64, 6.95 | 6.38, 7.62 s, 134-143 MB; 0.01: margin 0 19.5 | 16.9 s, RIM 16.7
| 21.4 s, 174 | 206 MB: no gain measurable here. (RIM was left off by default on that branch:
margin 0 itself misses 5 s on this box, and RIM is 1.04-1.28x it at 0.05 in the same run.) Tried and reverted: the first candidate's
stepover scaled by sqrt(aim / scallop the last step left): sample 1's candidates 163 -> 137 at
0.05 (356 -> 350 at 0.01), but sample4 ball1 then left 0.0111 at (54.82, 48.82) MISS: one cell
on the steep face (its neighbours 0.0043-0.0068) between passes 48.7834 and 48.8328, which the
planner measured at 0.0092 (0.0117 there with the ball 0.4973 out). Not yet looked into.

RIM was the default for a moment in session 13 (7ec8c50, reverted in 7779a44: on the daemon's
demo map it cost 26.7 s and 687 MB), and is the default again since session 14, once the rim's
fine lines were grouped per passes and polished per move, and the margin judged on the exact
distance to the outline (a cell-centre distance had kept positions past the cutter's reach on
a round outline: 1.08 mm of gouge in the demo map's RIM program). Kept inside the outline the
acceptance table missed on every sample's edge: max scallop at 0.01, margin 0 -> RIM, sample1
ball6 0.1135 (x 99.6) -> 0.0100, sample2 ball6 0.5452 -> 0.0098, sample3 ball6 0.1275 -> 0.0097,
sample4 ball1 0.0242 -> 0.0103. `--only acceptance` with the RIM default (session 14, every row
one program, gouge / max scallop / passes): sample1 ball6 0.0021 / 0.0100 / 280, bull6r1 0.0028 /
0.0098 / 439, flat6 0.05 0.0023 / 0.0486 / 973; sample2 ball6 0.0014 / 0.0098 / 264, bull6r1
0.0026 / 0.0097 / 354, flat6 0.0022 / 0.0488 / 401; sample3 ball6 0.0014 / 0.0097 / 252, bull6r1
0.0026 / 0.0099 / 359 (328 s to make), flat6 0.0023 / 0.0485 / 324; sample4 ball1 0.0037 / 0.0103
/ 324, bull1r0.25 0.0036 / 0.0102 / 417, flat1 0.0036 / 0.0508 / 386: all 12 OK. `--only
finishing --old-ref none` (quiet box, the "margin 0" row is the old default beside it): 0.05:
6.8 s / 141 MB (MISS 5 s), margin 0 6.0 s / 136 MB (1.15x), two bands 4.4 s wall; 0.01: 17.8 s /
186 MB (OK), margin 0 13.3 s (1.33x). Near the machine's travel the margin is cut to what the
travel leaves beside the map, with a header note (jobs._within_travel).

Session 15 (2026-12-04, quiet box): the stepover search's exponent taken from its last two
candidates and each pass started re-aimed (sample 1 at 0.05: 163 -> 134 candidates for 124
passes). `--only finishing --old-ref 68448e3`: 0.05: 5.0 s / 135 MB | 6.0 s / 132 MB (1.2x; at
the limit: whole-process medians of 5 pinned runs 5.59 | 6.37 s, imports included); 0.01: 15.3
s / 208 MB | 14.1 s / 209 MB (OK, one run). `--only acceptance`: 12 of 12 OK, gouge / max
scallop / passes: sample1 ball6 0.0021 / 0.0100 / 280, bull6r1 0.0030 / 0.0098 / 438, flat6
0.0022 / 0.0494 / 972; sample2 0.0014 / 0.0099 / 264, 0.0026 / 0.0098 / 353, 0.0022 / 0.0483 /
403; sample3 0.0015 / 0.0099 / 252, 0.0026 / 0.0101 / 369 (458 s to make), 0.0042 / 0.0490 /
321; sample4 ball1 0.0025 / 0.0100 / 325, bull1r0.25 0.0027 / 0.0104 / 417, flat1 0.0029 /
0.0504 / 386. A screened opening (a coarse one deciding where the fine one is needed) was
tried and reverted: at its lattice error as the tolerance sample 3's bull6r1 was left 0.0157
at its edge, at a tolerance the planner's contact test stands it saved ~10 % of the opening.

Session 19 (2026-12-04): the facets' window by rows and columns, a pass's envelope only
where it reaches, the shared-direction segment sweep and the min-plus product over the
positions a row reaches. `--only finishing --old-ref fc8aa2d`, one run: 0.05: 4.8 s / 133 MB
| 5.3 s / 133 MB, 124 passes (two cores 3.2 s wall); 0.01: 14.2 s / 209 MB | 13.5 s / 208 MB,
276 passes (two cores 8.9 s): this dome has no wall, so the facets never run here, and the
rest is one run's noise. `--only acceptance`: 12 of 12 OK, samples 1-3 as session 15's;
sample4 ball1 0.0027 / 0.0102 / 325, bull1r0.25 0.0025 / 0.0099 / 417, flat1 0.0028 /
0.0498 / 386 (the facets agree to 1.4e-13 mm, which moves a planner's search). `--only rim`:
12 of 12 OK, 0.00 % uncut everywhere; max scallop 0.0098-0.0102 on the 0.01 rows of samples
1-3, flat6 0.0494 / 0.0483 / 0.0539 (sample 3's corner), sample4 ball1 0.0102, bull1r0.25
0.0109, flat1 0.0521; gouge at most 0.0042 (sample3 flat6).

Session 20 (2026-12-04): on a plan's first step, the columns its placed pass (run off the
outline) touches nothing in are measured from that pass's axis, where the candidate leaves
the stock (ball and bull nose; cusps.py). The daemon's demo map (a ball seen from above, its
outline on a 74-degree face 8 mm above the base) at 0.05 on two cores: max scallop 2.1484 ->
0.0874 mm, uncut 0.70 -> 0.00 % of the reachable area. The same shape smaller (tests'
_ball_seen_from_above): ball6 1.6452 -> 0.0642, bull6r1 8.1569 -> 0.0627 (7.31 -> 0.00 %
uncut). A flat end keeps the old rule: measured, its passes on that wall gouged 0.0150.
Measured on every step (tried first), the planner crawled at pass ends mid-part: the demo
scan's map 6.6 -> 9.9 s and 126 -> 169 MB on two cores (the first step alone: 7.6 s, 132 MB),
and sample4 ball1's rim row went to 0.0113 (MISS) as its passes moved. `--only acceptance`
and `--only rim`: every row as session 19's (the first step on the samples' outlines is
unchanged). `benches/steep.py --only walls`: the same programs (33573 and 10310 lines).

Session 21 (2026-12-04): the links made in parts on the two cores (linking.py; the demo map's
program byte-identical). `--only finishing --old-ref none`: 0.05: 4.4 s / 140 MB, 124 passes
(two cores 2.6 s wall); 0.01: 11.7 s / 207 MB, 276 passes (7.5 s wall): OK, OK. `--only rim`
and `--only acceptance`: 12 of 12 OK each, every row as session 19's. `benches/steep.py
--only walls`: the same programs (33573 and 10310 lines), the same figures.

OpenCAMLib is a reference only, never a runtime dependency:
    .venv/bin/pip install opencamlib      (or: pip install -e '.[bench]'; Python 3.11 wheels)

The comparison: the same height map (sample 3 at 1 mm, 101 x 101) as a
triangle mesh of two triangles per cell (split along the same diagonal our
sampler uses, so both see the same surface), a 6 mm ball, zig-zag lines 1 mm
apart with points 0.1 mm apart. Times are medians of repeated runs in this
one process (the machine is shared and noisy); the ratio is what counts.

Session 11, main d72c918, `--only finishing --old-ref 13e7e57` on an idle box, new | old:
0.05: 4.9 s / 133 MB | 5.7 s / 174 MB (OK); RIM 7.4 s / 133 MB (1.50x margin 0's CPU);
0.01: 17.1 s / 151 MB | 18.3 s / 200 MB (OK); RIM 24.9 s / 163 MB (1.46x).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from appliance.cam.cutters import parse_cutter
from appliance.cam.dialects import check_fanuc, check_grbl
from appliance.cam.dropcutter import drop_grid, drop_lines
from appliance.cam.jobs import finishing_gcode, finishing_gcodes, verify_gcode
from appliance.cam.posts import DIALECT_NAMES
from appliance.cam.sampling import Sampler
from appliance.cam.seed import seed_gcode
from appliance.cam.zigzag import RIM, FinishSettings
from appliance.sim import surfaces
from appliance.surface.heightmap import HeightMap

RS274 = "/usr/bin/rs274"
# every dialect goes through LinuxCNC's interpreter (it reads them all, Fanuc's % and
# O0001 included); GRBL's and Fanuc's own rules are checked by ours as well
RULE_CHECKERS = {"grbl": check_grbl, "fanuc": check_fanuc}


def sample_map(name, step):
    s = surfaces.get(name)
    x0, x1, y0, y1 = s.bounds
    nx = int(round((x1 - x0) / step)) + 1
    ny = int(round((y1 - y0) / step)) + 1
    x = np.linspace(x0, x1, nx)
    y = np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(x, y)
    return HeightMap(x, y, s.height(X, Y))


def median_time(fn, repeats):
    ts, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), out


def ocl_mesh(hm, ocl):
    """Two triangles per cell, split from (i, j) to (i+1, j+1) like appliance.cam.sampling."""
    surf = ocl.STLSurf()
    P = [
        [ocl.Point(float(hm.x[i]), float(hm.y[j]), float(hm.z[j, i])) for i in range(hm.x.size)]
        for j in range(hm.y.size)
    ]
    for j in range(hm.y.size - 1):
        for i in range(hm.x.size - 1):
            p00, p10, p01, p11 = P[j][i], P[j][i + 1], P[j + 1][i], P[j + 1][i + 1]
            surf.addTriangle(ocl.Triangle(p00, p10, p11))
            surf.addTriangle(ocl.Triangle(p00, p11, p01))
    return surf, P


def bench_dropcutter(quick):
    print(
        "== drop-cutter: ours vs OpenCAMLib (sample3 at 1 mm, 6 mm ball, lines 1 mm apart, points 0.1 mm) =="
    )
    hm = sample_map("sample3", 1.0)
    cutter = parse_cutter("ball6")
    lines = np.arange(0, 101, 10 if quick else 1).astype(float)
    n = 1001
    origins = np.column_stack([np.zeros(lines.size), lines])
    sampler = Sampler(hm, edge_step=0.05)
    t_ours, ours = median_time(
        lambda: drop_lines(sampler, cutter, origins, (1.0, 0.0), n, 0.1), 3 if quick else 5
    )
    npts = ours.size
    print(f"ours: {npts} points in {t_ours:.3f} s (median)")
    try:
        from opencamlib import ocl
    except ImportError:
        print("OpenCAMLib not installed: `.venv/bin/pip install opencamlib` (Python 3.11 wheels) to compare")
        return
    surf, keep = ocl_mesh(hm, ocl)
    oc = ocl.BallCutter(cutter.diameter, 50.0)

    def run_ocl():
        bdc = ocl.BatchDropCutter()
        bdc.setSTL(surf)
        bdc.setCutter(oc)
        xs = 0.1 * np.arange(n)
        for y in lines:
            for x in xs:
                bdc.appendPoint(ocl.CLPoint(float(x), float(y), -100.0))
        bdc.run()
        return np.array([[p.x, p.y, p.z] for p in bdc.getCLPoints()])

    t_ocl, cl = median_time(run_ocl, 1)
    # OpenCAMLib returns the points in the order given (check, then compare)
    xs = np.tile(0.1 * np.arange(n), lines.size)
    ys = np.repeat(lines, n)
    assert np.allclose(cl[:, 0], xs) and np.allclose(cl[:, 1], ys), "OpenCAMLib reordered the points"
    diff = ours.ravel() - cl[:, 2]
    interior = (xs >= 3) & (xs <= 97) & (ys >= 3) & (ys <= 97)
    print(f"OpenCAMLib: {npts} points in {t_ocl:.2f} s (one run: it is the slow side; its default threads)")
    print(f"speed-up: {t_ocl / t_ours:.0f}x (target >= 50x)")
    print(
        f"max |ours - OpenCAMLib|: {np.max(np.abs(diff)):.5f} mm over all points, "
        f"{np.max(np.abs(diff[interior])):.5f} mm more than the radius inside the edge "
        f"(target <= 0.002); ours lower by at most {max(0.0, -diff.min()):.5f} mm, "
        f"higher by at most {max(0.0, diff.max()):.5f} mm"
    )


def bench_fullmap(quick):
    print("== drop-cutter on a whole map: 100 x 100 mm at 0.1 mm, 6 mm ball ==")
    cutter = parse_cutter("ball6")
    # the map as the benchmark's 1 mm mesh read at 0.1 mm, and a map sampled at 0.1 mm
    # itself (ten times the edge segments along its boundary)
    for step in (1.0, 0.1):
        sampler = Sampler(sample_map("sample3", step), edge_step=0.05)
        t, g = median_time(
            lambda sampler=sampler: drop_grid(sampler, cutter, 0.0, 0.0, 1001, 1001, 0.1), 1 if quick else 3
        )
        print(f"sample3 map at {step:g} mm: 1001 x 1001 tool heights in {t:.2f} s (median)")


def run_rs274(text, folder):
    """LinuxCNC's interpreter on a program: (exit code, its complaint or '')."""
    src = Path(folder) / "p.ngc"
    src.write_text(text)
    r = subprocess.run(
        [RS274, "-g", str(src), str(Path(folder) / "out.txt")],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=600,
    )
    return r.returncode, (r.stderr or r.stdout).strip().splitlines()[-1:] if r.returncode else []


def bench_dialects(quick):
    """Every dialect of one finishing plan for a dissertation sample, each through its checker."""
    name = "sample3"
    st = (
        FinishSettings(parse_cutter("ball6"), scallop=None, stepover=1.0)
        if quick
        else FinishSettings(parse_cutter("ball6"), scallop=0.01)
    )
    print(
        f"== dialects: {name}, ball6, {'stepover 1 mm' if quick else 'scallop 0.01 mm'}; "
        "each through LinuxCNC's `rs274 -g`, GRBL and Fanuc through our rule checkers too =="
    )
    hm = sample_map(name, 1.0)
    jobs = finishing_gcodes(hm, st, DIALECT_NAMES)
    have_rs274 = Path(RS274).exists()
    if not have_rs274:
        print("rs274 not installed (apt-get install linuxcnc-uspace): only the rule checkers run")
    with tempfile.TemporaryDirectory() as tmp:
        for d, job in jobs.items():
            lines = job.text.splitlines()
            how = []
            if have_rs274:
                t = time.perf_counter()
                rc, why = run_rs274(job.text, tmp)
                how.append(
                    f"rs274 -g exit {rc} in {time.perf_counter() - t:.1f} s{' ' + ' '.join(why) if why else ''}"
                )
            if d in RULE_CHECKERS:
                problems = RULE_CHECKERS[d](job.text)
                how.append(
                    f"check_{d}: {len(problems)} problems" + (f" (first: {problems[0]})" if problems else "")
                )
            print(
                f"{d:12s} {len(lines):7d} lines, longest {max(len(l) for l in lines):3d} chars: {'; '.join(how)}",
                flush=True,
            )


# sample -> cutters (name, requested scallop). Sample 4 is 10 x 10 mm and very
# steep: a 6 mm cutter does not fit its features, so it gets 1 mm tools.
PLAN = {
    "sample1": [("ball6", 0.01), ("bull6r1", 0.01), ("flat6", 0.05)],
    "sample2": [("ball6", 0.01), ("bull6r1", 0.01), ("flat6", 0.05)],
    "sample3": [("ball6", 0.01), ("bull6r1", 0.01), ("flat6", 0.05)],
    "sample4": [("ball1", 0.01), ("bull1r0.25", 0.01), ("flat1", 0.05)],
}


def bench_acceptance(quick, only_sample=None, only_cutter=None):
    print(
        "== acceptance: finishing programs verified by simulated milling (sim lattice 0.1 mm; sample4 0.02 mm) =="
    )
    print("sample   cutter      req.scallop  passes  gouge     scallop max  mean     | dissertation gouge")
    for name, cuts in PLAN.items():
        if only_sample and name != only_sample:
            continue
        step = 0.2 if name == "sample4" else 1.0
        hm = sample_map(name, step)
        res = 0.02 if name == "sample4" else 0.1
        d = 0.02 if name == "sample4" else 0.1
        top = float(np.nanmax(hm.z))
        for cname, h in cuts[:1] if quick else cuts:
            if only_cutter and cname != only_cutter:
                continue
            cutter = parse_cutter(cname)
            t = time.perf_counter()
            # default chord (h / 20, at most 0.002): a move may stand that far above the tips,
            # which adds to the scallop directly
            job = finishing_gcode(hm, FinishSettings(cutter, scallop=h, resolution=d))
            tg = time.perf_counter() - t
            rep, _ = verify_gcode(job.text, hm, resolution=res, edge_band=max(0.5, 5 * res))
            drep, _ = verify_gcode(
                seed_gcode(hm),
                hm,
                cutter=cutter,
                z_zero=top,
                resolution=res,
                edge_band=max(0.5, 5 * res),
            )
            ok = rep.gouge <= 0.005 and abs(rep.scallop_max - h) <= 0.1 * h
            dev = rep.deviation[rep.measured]
            p999 = float(np.percentile(dev, 99.9)) if dev.size else float("nan")
            print(
                f"{name:8s} {cname:11s} {h:<12g} {job.summary['passes']:6d}  {rep.gouge:.4f}    "
                f"{rep.scallop_max:.4f}       {rep.scallop_mean:.4f}   | {drep.gouge:.3f}   "
                f"{'OK' if ok else 'MISS'}  (max at x={rep.scallop_at[0]:.1f} y={rep.scallop_at[1]:.1f}, "
                f"99.9th percentile {p999:.4f}; gen {tg:.0f} s, {job.runtime_s / 60:.0f} min to mill)",
                flush=True,
            )


def bench_rim(quick, only_sample=None, only_cutter=None, compare=False):
    """Issue 20's rim: the default program (passes run off the outline by the cutter's radius)
    verified over the whole part, no edge band; with --rim-compare, margin 0 beside it."""
    print(
        "== rim: default finishing programs verified over all of the part (edge band 0; positions up to a "
        "radius past the outline count as reaching it) =="
    )
    print(
        "sample   cutter      req.scallop  margin  gouge    scallop max (at)          uncut % of reach  "
        "reach mm^2  verdict"
    )
    for name, cuts in PLAN.items():
        if only_sample and name != only_sample:
            continue
        step = 0.2 if name == "sample4" else 1.0
        res = 0.02 if name == "sample4" else 0.1
        hm = sample_map(name, step)
        for cname, h in cuts[:1] if quick else cuts:
            if only_cutter and cname != only_cutter:
                continue
            cutter = parse_cutter(cname)
            for margin in (RIM, 0.0) if compare else (RIM,):
                kw = {"margin": margin}
                job = finishing_gcode(hm, FinishSettings(cutter, scallop=h, resolution=res, **kw))
                rep, _ = verify_gcode(job.text, hm, resolution=res)
                ok = (
                    rep.gouge <= 0.005 and rep.uncut_reachable <= 0.01 and abs(rep.scallop_max - h) <= 0.1 * h
                )
                m = "R-d" if margin == RIM else f"{margin:g}"
                print(
                    f"{name:8s} {cname:11s} {h:<12g} {m:6s}  {rep.gouge:.4f}   {rep.scallop_max:.4f} "
                    f"({rep.scallop_at[0]:5.1f}, {rep.scallop_at[1]:5.1f})   {100 * rep.uncut_reachable:8.2f}"
                    f"          {rep.part_area - rep.unreachable_area:10.0f}  {'OK' if ok else 'MISS'}",
                    flush=True,
                )


# The finishing run the bench times, as a child process: CPU seconds and peak RSS are
# the child's own (ru_maxrss), imports included, so the figures are what a user's
# `inkslice toolpath` costs. The same code runs against an older checkout for the ratio.
FINISH_CHILD = r"""
import json, resource, sys, time
import numpy as np
from appliance.cam.cutters import parse_cutter
from appliance.cam.jobs import finishing_gcode
from appliance.cam.zigzag import FinishSettings
from appliance.sim import surfaces
from appliance.surface.heightmap import HeightMap
name, step, cutter, scallop = sys.argv[1], float(sys.argv[2]), sys.argv[3], float(sys.argv[4])
inside = "inside" in sys.argv[5:]
if "bands" in sys.argv[5:]:  # as the processing child and the commands plan: on two cores
    from appliance.forks import allow_workers
    allow_workers(2)
s = surfaces.get(name)
x0, x1, y0, y1 = s.bounds
x = np.linspace(x0, x1, int(round((x1 - x0) / step)) + 1)
y = np.linspace(y0, y1, int(round((y1 - y0) / step)) + 1)
X, Y = np.meshgrid(x, y)
hm = HeightMap(x, y, s.height(X, Y))
t, wall = time.process_time(), time.perf_counter()
kw = {"margin": 0.0} if inside else {}  # the default is zigzag.RIM: the rim finished
job = finishing_gcode(hm, FinishSettings(parse_cutter(cutter), scallop=scallop, **kw))
cpu = time.process_time() - t
workers = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"cpu": cpu, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "passes": job.summary["passes"], "lines": job.summary["lines"],
                  "wall": time.perf_counter() - wall, "workers_cpu": workers.ru_utime + workers.ru_stime}))
"""

OLD_REF = "30fd316"  # the planner before issue 20 (issue 20 measured it)


def run_finishing(checkout, name, step, cutter, scallop, inside=False, bands=False):
    import json
    import os

    env = dict(os.environ, PYTHONPATH=str(checkout))
    r = subprocess.run(
        [sys.executable, "-c", FINISH_CHILD, name, str(step), cutter, str(scallop)]
        + (["inside"] if inside else [])
        + (["bands"] if bands else []),
        cwd=str(checkout),
        env=env,
        capture_output=True,
        text=True,
        timeout=3600,
    )
    if r.returncode:
        raise RuntimeError(f"finishing in {checkout} failed: {r.stderr.strip().splitlines()[-1:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def old_checkout(ref, folder):
    """A detached `git worktree` of `ref` in `folder`, or None (no git, unknown ref)."""
    repo = Path(__file__).resolve().parent.parent
    r = subprocess.run(
        ["git", "-C", str(repo), "worktree", "add", "--detach", str(folder), ref],
        capture_output=True,
        text=True,
    )
    return Path(folder) if r.returncode == 0 else None


def bench_finishing(quick, old_ref=OLD_REF):
    """Issue 20's speed case: sample 1 (a Gaussian dome, 100 x 100 mm) from a 0.5 mm map, 6 mm ball."""
    print(
        f"== finishing: sample1 (100 x 100 mm dome) from a 0.5 mm map, ball6; each run a child process, "
        f"CPU = its process_time, peak = its ru_maxrss; 'old' = a git worktree of {old_ref} run the same way =="
    )
    print(
        "scallop  new CPU s  new peak MB  passes |  old CPU s  old peak MB  passes | CPU ratio  peak ratio  target"
    )
    repo = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        old = None if old_ref in ("", "none") else old_checkout(old_ref, Path(tmp) / "old")
        if old_ref not in ("", "none") and old is None:
            print(f"(could not make a git worktree of {old_ref}: no comparison)")
        try:
            for h, cpu_max in ((0.05, 5.0), (0.01, 20.0))[: 1 if quick else 2]:
                new = run_finishing(repo, "sample1", 0.5, "ball6", h)
                row = f"{h:<8g} {new['cpu']:9.1f}  {new['peak_mb']:11.0f}  {new['passes']:6d} |"
                if old is not None:
                    o = run_finishing(old, "sample1", 0.5, "ball6", h)
                    row += (
                        f" {o['cpu']:9.1f}  {o['peak_mb']:11.0f}  {o['passes']:6d} | "
                        f"{o['cpu'] / new['cpu']:8.1f}x  {o['peak_mb'] / new['peak_mb']:9.1f}x"
                    )
                else:
                    row += "         -            -       - |        -          -"
                ok = new["cpu"] <= cpu_max and new["peak_mb"] <= 250
                print(f"{row}  <= {cpu_max:g} s, <= 250 MB: {'OK' if ok else 'MISS'}", flush=True)
                # the same planned in two bands on two cores (cam/bands.py), as the daemon's
                # processing child and `inkslice toolpath` plan it: the wait, not the CPU
                b = run_finishing(repo, "sample1", 0.5, "ball6", h, bands=True)
                print(
                    f"  bands  wall {b['wall']:.1f} s against {new['wall']:.1f} s in one "
                    f"({new['wall'] / b['wall']:.2f}x); CPU {b['cpu']:.1f} s here + {b['workers_cpu']:.1f} s "
                    f"in the worker; {b['passes']} passes",
                    flush=True,
                )
                # the same kept inside the outline (margin 0, the default until session 14),
                # for what finishing the rim costs
                r = run_finishing(repo, "sample1", 0.5, "ball6", h, inside=True)
                print(
                    f"  margin 0 {r['cpu']:7.1f}  {r['peak_mb']:11.0f}  {r['passes']:6d} | "
                    f"the default (the rim finished) takes {new['cpu'] / r['cpu']:.2f}x its CPU, "
                    f"{new['peak_mb'] / r['peak_mb']:.2f}x its peak",
                    flush=True,
                )
        finally:
            if old is not None:
                subprocess.run(
                    ["git", "-C", str(repo), "worktree", "remove", "--force", str(old)], capture_output=True
                )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("dropcutter", "fullmap", "acceptance", "dialects", "finishing", "rim"))
    ap.add_argument("--rim-compare", action="store_true", help="rim: margin 0 programs beside the default")
    ap.add_argument("--old-ref", default=OLD_REF, help="finishing: the commit to compare with ('none': skip)")
    ap.add_argument("--sample", help="acceptance, rim: only this sample (sample1..sample4)")
    ap.add_argument("--cutter", help="acceptance, rim: only this cutter (as named in the table)")
    a = ap.parse_args(argv)
    if a.only in (None, "dropcutter"):
        bench_dropcutter(a.quick)
    if a.only in (None, "fullmap"):
        bench_fullmap(a.quick)
    if a.only in (None, "dialects"):
        bench_dialects(a.quick)
    if a.only in (None, "acceptance"):
        bench_acceptance(a.quick, a.sample, a.cutter)
    if a.only in (None, "rim"):
        bench_rim(a.quick, a.sample, a.cutter, a.rim_compare)
    if a.only in (None, "finishing"):
        bench_finishing(a.quick, a.old_ref)


if __name__ == "__main__":
    main()
