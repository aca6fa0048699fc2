"""The harsh bench: does a waterline survive what a bad day at the bench throws at it?

The `harsh` effects preset (sim/effects.py) puts on every frame glare that drifts, jitters,
flickers and vanishes from frame to frame, drifting dust and bubbles, salt and pepper, JPEG
q85, 1.5 % lamp flicker, up to 0.05 mm of lateral stage wobble, a rippling surface, and a
meniscus that is not the first model's. As a user would, the bench calibrates the camera
from rendered chessboards and commissions the meniscus from a harsh scan of the reference
ball (benches/meniscus.py's commission), then scans each part and processes it.

Per part it prints Ea, the interior's 99th percentile (nodes more than 3 mm inside the
outline) and the largest error, in mm, against the part's truth, and the map's area beyond
the part (benches/outline.py: material a program would leave standing where there is none). Targets (issue 18):
Ea <= 0.05 mm, interior p99 <= 0.2 mm, max <= 1 mm. And the uncertainty map's honesty: of
the cells off by more than 0.1 mm, the share it marks uncertain (uncertainty_mm > 0.1; target
>= 80 %), beside the share of all cells it marks (benches/uncertainty.py).

Measured (2 December 2026, 1 mm steps; meniscus commissioned 2.507 mm / 0.26 deg / weight 0.95
against the renderer's 2.5 mm / 0 / curved), Ea / interior p99 / max in mm and the share of
the cells off by > 0.1 mm that the map marks (of how many) / the share of all cells marked:
(a) the bench as it was, its first frame the first to show the part; (b) scans from an empty
frame above the top (new renders); (c) = (b) with the runner's refinement frames and the
uncertainty changes of 2 December (inradius of the top, no lattice guess, the ink's bound):
    sample1    (a) 0.0139 0.039 0.248 100% of 17 18.8%  (b) 0.0136 0.039 0.260  95% of 19 18.8%
               (c) 0.0195 0.064 1.169  98% of 46 17.5%  (main's processing at 17:04; at 16:42 the
               same scan gave 0.0123 0.039 0.260: 61e9653/b27d783 made its max worse)
    sample2    (a) 0.0255 0.068 0.322  87% of 53 43.7%  (its (a) render with refinement frames:
               0.1035 0.559 3.627: four half levels at 21.5-24.5 make it worse, not looked into)
    sample3    (a) 0.0260 0.195 0.466  87% of 131 38.0%
    sample4    (a) 0.4383 0.507 2.758 100% (all marked)  (b) 0.5007 0.448 4.835 100% (all)
               (c) 0.5007 0.448 4.835 100% (all)
    twin-peaks (a) 0.0729 0.473 0.731  92% of 413 52.3%  (b) 0.0343 0.317 0.494  84% of 148 54.2%
               (c) 0.0235 0.115 0.389  26% of 31 14.0%   (the refinement frames place its flats)
    plateau    (a) 0.8891 4.352 4.604  98% of 2249 97.6%  (b) 0.3265 0.939 1.701 91% of 1418 83.5%
               (c) 0.1315 0.944 1.712  40% of 788 18.1% (without the ink's bound: 22 % of 788)
    ring       (a) 0.1325 0.974 1.412  53% of 450 86.6%  (b) 0.1330 0.973 1.296  55% of 466 86.6%
               (c) 0.1444 0.968 1.328  50% of 534 55.4%
  held out (shapes the uncertainty map was not tuned on), (c):
    crater      0.0965 1.100 1.385  42% of 291 15.6%
    steep-front 0.0172 0.072 0.345  73% of 33   7.2%
  all (c), tuned: 75.7 % of 3147 cells off by > 0.1 mm marked, 41 % of the cells marked (mean);
  held out: 45.1 % of 324, 11.4 % marked. The honesty target holds on neither.
(d) = (c) with each frame registered on the walls it shares with its neighbours
(surface/registration.py, 2 December, same renders): sample4 0.5007 0.448 4.835 -> 0.2455 0.363
1.937; sample1 0.0195 0.064 1.169 -> 0.0191 0.069 0.921. The seed table's figures are unchanged
(without play the offsets stay under registration.NOTHING_TO_DO_MM and nothing moves).
(e) the whole bench on today's main (3 December, 0b07181: registration counts only the frame
pairs whose shifts close a triangle), fresh renders from above with the runner's refinement
frames, meniscus 2.507 mm / 0.26 deg / 0.95, Ea / interior p99 / max mm, honest share of (cells):
    sample1    0.0158 0.042 0.558  94% of 31    17.6% marked
    sample2    0.0961 0.211 0.494  37% of 619   15.0%  (16 refinement frames at 21.6-24.4; the
               fit stands 0.1-0.2 mm low over the lower saddle, unmarked; the older render with
               4 of them, same code: 0.0208)
    sample3    0.0618 0.155 0.553  65% of 289   18.7%  (7 refinement frames on the older render:
               0.0377)
    sample4    0.2456 0.363 1.937 100% (all)
    twin-peaks 0.0519 0.270 1.104  62% of 173   19.0%  ((c) 0.0235 0.115 0.389 before registration)
    plateau    0.1322 0.949 1.705  40% of 805   18.4%
    ring       0.1435 0.967 1.334  49% of 524   55.5%
  held out: crater 0.0965 1.100 1.385  42% of 291  15.6%; steep-front 0.0141 0.061 0.193  11% of 9
  5.8%. All tuned: 68.5 % of 4166 marked (34.9 % of the cells, mean); held out: 41.0 % of 300.
  Within targets: sample1 (but max 0.558), steep-front. Over: sample2/3 Ea (their refinement
  frames), sample4, twin-peaks, plateau, ring; the honesty target on neither set.
(f) = (e) with the meniscus rise unsure where its face does not stay open (surface/uncertainty.py
_shared_meniscus: a tenth of how much more a face within a capillary length rises, and of the
rise itself within a capillary length below the top of the node's piece), same renders, honest
share before -> after (share marked): sample3 65 -> 65 % (18.7 -> 19.0), twin-peaks 62 -> 73 %
(19.0 -> 20.7), plateau 40 -> 67 % (18.4 -> 30.7), ring 49 -> 97 % (55.5 -> 71.6); sample1, 2, 4
unchanged. Crater 42 -> 95 % (15.6 -> 27.2), steep-front 11 -> 100 % of 9 (5.8 -> 7.0). All tuned
80.3 % of 4166 (39.2 % marked, mean); held out 95.0 % of 300 (17.1 %). The share 0.1 was chosen
looking at the ring, plateau and crater together, so the crater is no longer strictly held out.
Heights are untouched (Ea / p99 / max as (e)); sample2's fresh render still misses 63 % of its 619.
(g) = (f) with an edge's history counted in level steps, not frames (surface/perspective.py
_history, 3 December), same renders (/tmp/harsh-h), meniscus 2.507 mm / 0.26 deg / 0.95.
Why sample 2 got worse with more frames: on its one render, processed with its refinement
frames left out, 4 of them (the half steps) or all 16, Ea 0.0288 / 0.0208 / 0.0961 mm (8 of
them, the half and quarter steps: 0.1105). Per first-exposure frame the 16-frame fit stood
low everywhere, 0.05-0.09 mm through the refined levels and 0.25-0.6 mm at the top and the
foot, and its true levels came out up to 0.3 mm low; without registration it was as bad
(0.0891). The walls' edge brackets followed each wall point's raised edge only two frames
up; two refinement frames 0.06-0.25 mm apart were then the whole history, too short a stretch
of ray to match an edge the stage's play had moved, so the edges started afresh a fraction
of a step high and the rims, the fit's volume and the levels went wrong from there. With
eight frames of history: 0.0169; with two level steps (a frame under half the scan's longer
steps below the last counted one is no step; with the median step the refinement frames deep
down, whose true gaps the displacement stretches, still counted: 0.0628): 0.0192. Uniform
scans keep the same two frames. Ea / interior p99 / max mm, honest share of (cells), marked:
    sample1    0.0158 0.042 0.558  97% of 29    17.6%  (unchanged)
    sample2    0.0192 0.048 0.183 100% of 13    16.7%  ((f) 0.0961 0.211 0.494, 37 % of 619)
    sample3    0.0381 0.102 0.213  78% of 82    16.4%  ((f) 0.0618 0.155 0.553, 65 % of 289)
    sample4    0.2456 0.363 1.937 100% of 1725 100%    (no refinement frames: unchanged)
    twin-peaks 0.0519 0.270 1.104  73% of 173   20.7%  (unchanged)
    plateau    0.1323 0.949 1.705  68% of 805   30.8%  (unchanged to 0.0001)
    ring       0.1433 0.967 1.334  97% of 521   71.6%
  held out: crater 0.0965 1.100 1.385  95% of 292  27.2%; steep-front 0.0141 0.061 0.193 100% of 9
  7.0%. All tuned: 89.9 % of 3348 marked (39.1 % of the cells, mean); held out 95.0 % of 301.
  Looked at while finding and choosing the rule: sample 2 only (no held-out shape).
  Within targets now: sample1 (but max 0.558), sample2, sample3 (Ea 0.038, p99 0.10, max
  0.21), steep-front. Over: sample4, twin-peaks, plateau, ring (their errors sit where (f)
  and the note below say); the honesty target holds on both sets.
  Twin-peaks is registration's (same render, (g)'s code, register_frames off): 0.0236 0.115
  0.389 against 0.0519 0.270 1.104 with it. Its 14 moved frames' offsets against the play
  the renderer drew (default_rng([seed, frame]), centred): rms 0.037 mm of play, 0.054 left
  after the offsets (sample 2: 0.034, 0.035 left): the offsets do not follow the play there.
(h) = (g)'s code (main 13e7e57) -> the same with two bounds of the fit (3 December), the same
renders (/tmp/harsh-hx; sample 2's is not (g)'s render: its 0.649 max is there on both sides),
meniscus 2.507 mm / 0.26 deg / 0.95. Cause, from per-cell error maps against the truth and
each node's first frame: the solve's smooth rise carried the 1-2 mm the shoulders need over
the ring's round crest (a tent 1.2 mm high under a frame at 19.98 that showed nothing) and
onto the plateau's flat top (+0.5..1.7 mm next to its rim, all nodes of the first frame);
and a face that came out at once was allowed a wall's rise (3.5 mm) above its bracket, so the
plateau's 10 mm base stood +0.3..0.65 next to the shoulder's foot. (1) the lowest empty frame
above the part caps a round summit, held during the top's solve (surface/summit.py; a first
band under step / 2 wide a side is a rim and gets no cap: sample 2, 3, 4 and twin-peaks);
(2) a face that came out at once stands above its bracket no more than the ink climbs a face
that flat (bracket over 2 mm: fitpass.flat_face_rise). Ea / interior p99 / max mm, honest
share of (cells) over 0.1 mm:
    sample1    0.0157 0.042 0.558  97% of 29   -> 0.0157 0.042 0.558 100% of 28  (unchanged heights)
    sample2    0.0208 0.048 0.649  93% of 28   -> 0.0208 0.048 0.649  93% of 28   (unchanged)
    sample3    0.0366 0.086 0.440  98% of 48   -> 0.0366 0.086 0.440  98% of 48   (unchanged)
    sample4    0.2455 0.363 1.937 100% of 1725 -> 0.2455 0.363 1.937 100% of 1725 (unchanged)
    twin-peaks 0.0519 0.270 1.104  73% of 173  -> 0.0407 0.121 0.814  77% of 142  ((2) alone;
               with (2) off the same figures as before)
    plateau    0.1323 0.949 1.705  67% of 806  -> 0.0782 0.558 0.664  88% of 344  ((1) capped
               after the solve: 0.0986 0.550 0.663; with (2) 0.0844 0.550 0.663)
    ring       0.1431 0.968 1.328  97% of 522  -> 0.0600 0.207 1.142 100% of 281  ((1) after the
               solve: 0.0815 0.326 1.096)
  held out: crater 0.0965 1.100 1.385  95% of 291 -> 0.0393 0.202 0.291  92% of 121;
  steep-front 0.0141 0.061 0.193 100% of 9 -> 0.0153 0.093 0.256  54% of 13 (worse, within
  the targets: (2) moved its apron, 0.0152 0.090 0.193 with (1) after the solve).
  Honesty (from the rounded shares): all tuned 90.0 % of 3331 -> 97.0 % of 2596 marked (42 %
  of the cells, mean), held out 95.2 % of 300 -> 88.3 % of 134: the target holds on both.
  Within targets now: sample1, sample2, sample3, twin-peaks (Ea, p99 and max), crater, steep-
  front. Over: sample4 (untouched), plateau (Ea, p99: the shoulder's foot, below), ring (p99
  by 0.007, max: two wall-foot edge cells at the hole and the outer rim).
(i) = (g)'s code (main 13e7e57) with registration's gate (3 December, _plays: frames move only
where consecutive shifts are anti-correlated as play makes them), same renders, before (h)
landed beside it (the two together not measured yet): twin-peaks (ratio +0.04) is no longer
moved, 0.0519 0.270 1.104 -> 0.0235 0.115 0.389; plateau (+0.04) no longer moved, 0.1323 ->
0.1315 0.944 1.712; sample1-4 (-0.27, -0.10, -0.05, -0.44) and steep-front (-0.07) move the
same frames as before (0.0157, 0.0208, 0.0366, 0.2455); crater and ring moved nothing either way.
What is left, from per-cell error maps: sample 4 (10 mm across, slopes 4-10) is the stage
wobble and the meniscus, not glare: rendered without the wobble its Ea is 0.249, without
wobble, glare, dust and the image's noise 0.142 (the curved contact line on a part that is
all within a capillary length of its walls). The 0.05 mm wobble is random per frame and no
calibration knows it: registering each frame on the walls it shares with its neighbours
would be the vision rule to try. Plateau, after (h): the shoulder's concave foot, r 34-40 mm
from its axis: the ink wets the foot longer than the base beside it (nodes at r 35.5-37 come
out at 9.3 mm, those at 37.5-41 at 9.9), the shoulder above stands 0.2-0.4 low (its rise
1.05 where its slope asks 1.6) and the base's first 2 mm (not yet a face that came out at
once) +0.35..0.45 high. Ring, after (h): the crest held flat at the cap, +0.15 over r 26-34
mm where the truth falls to 19.75, and the wall-foot edge cells at r 15 and 45.

(j) the whole bench on main d72c918 (3 December, session 11: the fit's two bounds, the
registration's play gate, the level-top smoothing reverted), the same /tmp/harsh-hx renders,
one part at a time on an idle core. Ea / interior p99 / max mm, honest share of (cells):
    sample1    0.0157 0.042 0.558 100% of 28      sample2    0.0323 0.101 0.440  98% of 111
    sample3    0.0221 0.054 0.447  97% of 33      sample4    0.2455 0.363 1.937 100% of 1725
    twin-peaks 0.0235 0.115 0.389  32% of 31      plateau    0.0781 0.560 0.644  88% of 339
    ring       0.0600 0.207 1.142 100% of 281
  held out: crater 0.0393 0.202 0.291 92% of 121, steep-front 0.0153 0.093 0.256 54% of 13.
  Honest share: tuned 97.4 % of 2548, held out 88.1 % of 134 (target 80 %). Within all three
  targets: samples 1-3, twin-peaks, crater, steep-front. Over: sample4, plateau, ring.
  With the level-top smoothing (fb7364e, since reverted) the plateau was 0.4105 / 0.221 /
  4.828 and twin-peaks' max 1.199.
(k) the contact lines' bend averaged over the trusted top only (3 December 2026, session 12,
48472d7; surface/contact_lines.py contact_line_curvature), fresh renders in one folder
(/tmp/s4-harsh), meniscus 2.507 mm / 0.26 deg / 0.95. What sample 4's error is, taking the
renderer's effects off one at a time (new renders, main's code): as drawn 0.2454; without
play and ripple 0.337 (so play is not what is left); with only displacement and the
meniscus 0.142 / p99 0.335 - the meniscus correction alone fails the targets. On that last
render the fit of the apparent surface is 0.025 mm from the renderer's exact one, but the
top solved from the EXACT apparent surface is 0.134 off; with the renderer's own contact-line
curvature in the solve, 0.004. The bend (kappa l_c ~ 1 on this part: the rise's curvature
factor spans 0.5-1.4) was averaged over nearest-filled nodes off the part and over the
solve's untrusted rim. Averaged over the trusted top alone, Ea / interior p99 / max mm,
before -> after, the same renders:
    sample4    0.2454 0.362 1.937 -> 0.2241 0.353 2.118  (physics-only render: 0.142 -> 0.112)
    sample1    0.0157 0.042 0.558 -> 0.0158 0.041 0.567
    sample3    0.0381 0.102 0.213 -> 0.0398 0.103 0.219  (this folder's render; (j)'s was 0.0221)
    plateau    0.0781 0.560 0.644 -> 0.0782 0.564 0.643
  What is left on sample 4: the renderer takes a contact line's bend from its top continued
  past the outline by the part's formula (sample 4's saddle, whose kappa is odd about x = 45:
  0 on that edge); a scan knows no such continuation. With that continuation in the solve
  (true top, 3 mm past the outline) the exact apparent surface gives 0.004 and the fitted one
  0.029 on the lattice; the trusted-top mean 0.10, nearest fill 0.13, Taylor continuation of the
  solved top 0.09-0.15, more Levenberg-Marquardt steps no better. Sample 4 stays over all three
  targets (its left, gentle third +0.2..0.3 mm; the max at the y = 45 outline).

(l) Sample 4's 0.2241 / 0.353 / 2.118 taken apart (3 December 2026, session 13, main ad05d23, the
(k) renders; sample 4 re-rendered with one effect changed at a time, seed 1; Ea / p99 / max mm):
  - the contact lines' bend is the largest part: the solve fed the renderer's own bend (its top
    continued past the outline) gives 0.1247 / 0.087 / 1.958 on the same render; a render with
    only displacement and the harsh meniscus 0.1153 (commissioned file; the renderer's 2.5 mm
    and weight 1: 0.1016) -> 0.0218 with the renderer's bend; rendered without the bend (and
    solved without it) 0.0310, with displacement alone 0.0188. The solve's bend is
    shrunk towards 0 where the true one is strongest (+0.37/mm at x 46-48, y 48-51 -> +0.2;
    -0.35 along y 45-47 -> -0.1): the top there +0.3 and -0.4..-0.6 mm. Its three fine steps
    do not settle: with twelve, the top's mean error swings 0.06-0.10 mm from step to step.
  - the stage play is not: the registration's offsets against the play the renderer drew
    (default_rng([seed, frame]): r = 0.05 sqrt(u), angle 2 pi u) rms 0.025 mm left of 0.037;
    undoing the TRUE play instead gives 0.258 / 0.338 / 5.34 (worse; with the true bend too,
    0.199, against 0.125 with the registration's own offsets: the rim within 1 mm of the outline
    0.57 / 0.26 mm, not looked into). Without registration 0.448; rendered without play 0.2037.
  - the images: rendered without the bend and solved without it, 0.108 / 0.087 / 7.46; the
    error then sits within 3 mm of the outline (interior p99 0.087).
  - its Ea is not stable to a few hundredths: the registered frames moved by a further random
    0.005 mm each (seeds 1-3) give 0.2147 / 0.2578 / 0.2375 (p99 0.36-0.37), the true play undone
    plus the same 0.197-0.262. The swing sits on the near-flat strip y 45-47, x 45-50 (truth
    21.2-22.3): its apparent surface stays 0.51 below the truth in every case, but the solved
    rise over it is +0.59 in one and +0.66 -> 0.86 -> 1.05 over the three passes in another (the
    strip +0.09 or +0.53 mm; no ink floor above the truth there). Single-render comparisons of
    this part under ~0.04 mm are noise until the solve is made stable on that strip.
  Tried, not kept (sample 4 harsh / physics2): the top smoothed 0.3 mm before its level
  curves' bend 0.183 / 0.117 (p99 0.353 -> 0.102 on harsh; physics2 0.0840 worse at its
  y = 45 strip and the y = 55 rim), over the footprint only 0.163 / 0.119, 0.15 mm 0.173 / 0.100;
  the bend under-relaxed (0.3-0.4) over 8-20 fine steps 0.212-0.223 / 0.096-0.098 (physics-only
  render 0.066); the bend's mean over the trusted top made locally linear (a plane's bend
  fitted, not averaged: on the true top 0.031 mm of rise error against 0.073) 0.262 / 0.098;
  three untrusted rim nodes, not two (contact_lines.RIM_UNTRUSTED): harsh sample 4 0.196-0.203
  over the four draws above (0.215-0.258 with two: steadier and lower), physics2 sample 4
  0.079-0.112 (0.062-0.164 with two), but on the same renders harsh sample3 max 0.219 -> 0.262,
  plateau 0.0778 -> 0.0798, physics2 crater 0.0544 -> 0.0582 (p99 0.610 -> 0.633), physics2
  sample4's own draw 0.0840 -> 0.1119 (sample1 harsh 0.0158 -> 0.0159, physics2 0.0106 -> 0.0096).
(m) The whole bench on main ad05d23 (session 13, fresh renders (kept), meniscus
2.507 mm / 0.26 deg / 0.95), Ea / interior p99 / max mm, honest share (cells off > 0.1 mm):
    sample1 0.0158 0.041 0.567 100% of 28   sample2 0.0193 0.049 0.227 100% of 7
    sample3 0.0399 0.103 0.219  79% of 90   sample4 0.2243 0.353 2.118 100% of 1626
    twin-peaks 0.0235 0.115 0.388 32% of 31 plateau 0.0778 0.564 0.643 88% of 339
    ring 0.0585 0.209 1.178 100% of 259
  all tuned: 96.6 % of 2380 marked (target >= 80 %: met), 38.0 % of the cells marked; held out
  crater 0.0385 0.202 0.232 92% of 122, steep-front 0.0155 0.093 0.256 54% of 13: 88.1 % of 135.
  Over the targets: sample4 (all three), plateau (Ea, p99), ring (Ea, p99 by 0.009, max 1.178).

(n) The level rows back, held where they run away (4 December 2026, session 16; see
benches/meniscus.py for the runaway and what was tried). (m)'s kept renders and meniscus file,
processed by main 0ee8c1a -> this, Ea / interior p99 / max mm:
    sample1    0.0158 0.041 0.567 -> 0.0154 0.041 0.547   sample2 0.0193 0.049 0.227 -> 0.0187 0.049 0.214
    sample3    0.0399 0.103 0.219 -> 0.0426 0.107 0.407   sample4 0.2243 0.353 2.118 -> 0.2097 0.337 2.106
    twin-peaks 0.0235 0.115 0.388 -> 0.0226 0.085 0.275   plateau 0.0778 0.564 0.643 -> 0.0373 0.201 0.295
    ring       0.0585 0.209 1.178 -> 0.0490 0.199 1.056
  held out: crater 0.0385 0.202 0.232 -> 0.0356 0.198 0.243, steep-front 0.0155 0.093 0.256 ->
  0.0144 0.085 0.151. Over the targets now: sample4 (all three), plateau (p99 by 0.001), ring
  (max by 0.056: at its crest, not looked into). The honesty share was not re-run.
(o) Session 17 (4 December 2026). Its two meniscus fixes are for an ink that dewets, and this one
wets: every figure of (n) is the same (all parts on 262e00f; plateau, ring and twin-peaks again on
f7f523f). The honesty share on (m)'s kept renders, 262e00f:
tuned 97.8 % of 2069 cells off by more than 0.1 mm marked (sample 4's 1572 all marked; the rest
451 of 497, 91 %), held out 93.1 % of 101 (crater 98.9 % of 91, steep-front 4 of 10). The ring's
max is not at its crest but at the outer foot (r 44, 64 deg): the wetting ink leaves a wet band
at r 43.0-43.6 in the 7.31 mm frame (the renderer's own contact lines have it: the apparent
surface dips there and rises again to 8.0 at the rim), and first exposure puts the nodes between
that band and the outline near the level above (8.5-8.6 where the truth's apparent height is
7.6-7.9): the top comes out +1.06. The plateau's p99 is its shelf next to the shoulder's foot:
nodes under 3 mm from the frame above's waterline get no face bracket (bracketing them too gave
p99 0.158, but held-out steep-front 0.085 -> 0.150 and crater Ea 0.0356 -> 0.0393: not kept).
(p) Session 22 (5 December 2026, main 5338250), fresh renders of the ring and the plateau,
meniscus commissioned again (2.507 mm / 0.26 deg / 0.95): ring 0.0487 0.199 1.060, 100 % of 196
cells over 0.1 mm marked (72.7 % of all); plateau 0.0372 0.201 0.295, 89 % of 107 (27.6 %). The
same places as (o): the ring's three worst cells at r 43.3-44.9, 62-64 deg (+1.02..1.06), where
the 7.31 mm frame's wet band meets the ink outside and its waterline dents in to r 43.24; the
plateau's at its shelf, r 35-44 (+0.22..0.30). Leaving first exposure's heights held at their
bracket's bound to the fit (0 or 0.1 of the bracket instead of 0.25): ring max 1.046 / 1.053.
(q) Session 24 (5 December 2026): first exposure leaves a refinement frame out of a node's cubic
where its waterline runs within half a lattice cell of its neighbour's (surface/exposure.py
_apart). The ring's worst cells (r 43.3-44.9, 62-64 deg) came out at 7.31 mm and were under at
8.63; the 8.94 mm (nominal) refinement frame's waterline ran 0.04 mm from the 9 mm one's there,
and the cubic through the two swung to the bracket's ceiling (8.63; the straight line 7.60).
(m)'s renders (main gives (n)'s figures on them to the digit), main 1388d48 -> this, Ea /
interior p99 / max mm, honest share of (cells):
    sample1    0.0154 0.041 0.547 100% of 27  -> unchanged
    sample2    0.0187 0.049 0.214 100% of 7   -> 0.0186 0.049 0.214 100% of 7
    sample3    0.0426 0.107 0.407  82% of 142 -> 0.0428 0.107 0.378  82% of 141
    sample4    0.2096 0.337 2.106 100%        -> unchanged
    twin-peaks 0.0226 0.085 0.275  44% of 18  -> unchanged
    plateau    0.0372 0.201 0.295  89% of 107 -> 0.0366 0.196 0.283  85% of 110
    ring       0.0487 0.199 1.060 100% of 196 -> 0.0396 0.198 0.437 100% of 146
  held out: crater 0.0358 0.199 0.234 -> 0.0359 0.199 0.237; steep-front unchanged (0.0144 0.085
  0.151). Honest share: tuned 97.5 % of 2021, held out 93.6 % of 109. Over the targets now:
  sample4 only. The ring's waterlines moved a further 0.005 mm a frame (draws 0-3): Ea 0.0443 ->
  0.0387, p99 0.193 -> 0.193, max 0.774 -> 0.454 on average, the worst max 1.060 -> 0.681.
  Tried, not kept: leaving out ANY waterline within half a cell of its neighbour (full steps too):
  ring 0.0398 0.1995 0.435, plateau 0.0287 0.105 0.176, but the demo sphere's rim (its steep side,
  full steps 0.25 mm apart) Ea 0.0135 -> 0.0370 and the occlusion bench's stepped block (clean)
  0.2905 -> 0.4549; only those steeper than three times the bracket: the sphere as bad; the
  straight line wherever the cubic leaves its bracket: ring 0.0635 (the 28 deg sector's nodes,
  whose 7.31 level curve is 3.4 mm off past a pinned rim, went from the floor to the middle);
  beside the finer steps, also a neighbour within half a cell and over ten times steeper than
  the bracket (the mesa's shoulder, curves 0.07 mm apart over a shelf 3.6 mm wide): plateau
  0.0288 0.110 0.235, but the occlusion bench's stepped block (clean) 0.2905 -> 0.4619: its 85
  deg walls over its tier are the same pattern, and there the cubic did better.
  The plateau's p99 is at its target's edge: the waterlines moved a further 0.005 mm a frame
  (draws 1-4) give 0.202 0.202 0.209 0.200 (0.196 on the render as it is).
(r) Then (7fd5656, reverted in 68a4057: see benches/meniscus.py) first exposure took out the edge
nodes no frame has inside, same renders, (q) -> that: sample1 0.0154 -> 0.0155, sample2 0.0186 0.049 0.214 ->
0.0186 0.048 0.208, sample3 0.0428 0.107 0.378 -> 0.0433 0.108 0.387, sample4 0.2096 0.337 2.106
-> 0.1984 0.334 1.995, twin-peaks and plateau unchanged, ring 0.0396 0.198 0.437 -> 0.0444 0.201
0.434 (p99 over by 0.001 again); crater 0.0359 0.199 0.237 -> 0.0375 0.197 0.301, steep-front
unchanged. Honest share: tuned 97.4 % of 2011, held out 92.4 % of 118. Over the targets: sample4
(all three), ring (p99, 0.201).
(s) Session 27 (5 December 2026): the exact side at a rim put back as at a wall's foot, and a
node seen under a face's silhouette before it came out left to the fit (9b7036c), (m)'s
renders, 6f27519 -> 9b7036c, Ea / interior p99 / max mm: sample2 0.0203 0.059 0.214 -> 0.0170
0.052 0.163, sample3 0.0430 0.107 0.439 -> 0.0429 0.105 0.481, sample4 0.2089 0.336 2.002 ->
0.1930 0.335 1.606, ring 0.0399 0.199 0.498 -> 0.0355 0.183 0.309, crater (held out) 0.0364
0.200 0.244 -> 0.0366 0.203 0.232; sample1, twin-peaks, plateau, steep-front unchanged. Over
the targets: sample4 (all three), crater's p99 by 0.003.
(t) Session 31 (6 December 2026, ab9b9cf: at a sharp edge a face keeps its own rise; see
benches/meniscus.py), (m)'s renders, 045a73c -> ab9b9cf: crater 0.0366 0.2026 0.232 -> 0.0367
0.1979 0.232, sample3 0.0429 0.1052 0.481 -> 0.0429 0.1053 0.481, sample4 0.1930 0.3351 1.606 ->
0.1923 0.3339 1.603; sample1, sample2, twin-peaks, plateau, ring, steep-front the same to the
digit. Over the targets: sample4 (all three).
(u) Session 32 (6 December 2026, 098e655: at a sharp edge a side is level where the fit or the
first-exposure heights are), (m)'s renders, 926816a -> 098e655: sample4 0.1923 0.3339 1.603 ->
0.1922 0.3337 1.602; the other eight the same to the digit. Over the targets: sample4 (all three).
(v) Session 33 (6 December 2026: in the rim band the lower of the level and the tied meniscus
solves; see benches/meniscus.py), renders made again this session (the same seeds), e986be5 ->
this, Ea / interior p99 / max mm: sample1 0.0153 0.042 0.551, sample2 0.0170 0.052 0.165, sample3
0.0429 0.105 0.480, sample4 0.1921 0.334 1.602, twin-peaks 0.0226 0.085 0.275, plateau 0.0370
0.196 0.447, ring 0.0354 0.183 0.309, steep-front 0.0144 0.085 0.151 (all eight unchanged); crater
0.0367 0.199 0.240 -> 0.0365 0.198 0.241. Honest share: tuned 97.5 % of 1942 (unchanged), held
out 92.6 % of 108 -> 92.2 % of 102. Over the targets: sample4 (all three).
(w) Session 34 (6 December 2026: near a wall inside the part the meniscus solve reads the top's
slope near the fit's; see benches/meniscus.py), (v)'s renders, ef2af92 -> this: sample4 0.1921
0.334 1.602 -> 0.1906 0.334 1.627; the other eight the same to the digit. Honest share: tuned
97.5 % of 1942 -> 97.5 % of 1960 (sample4's cells over 0.1 mm 1508 -> 1526, all marked), held
out 92.2 % of 102 (unchanged). Over the targets: sample4 (all three).
(x) Session 35 (6 December 2026: the nodes a face hid are no dewetted face's, and the ray over a
rim bounds a node seen hidden behind it without the ink's climb added; see benches/meniscus.py),
(v)'s renders, b68e5a7 -> this: all nine tuned and both held-out scans the same to the digit,
and so are the honest shares (tuned 97.5 % of 1960, held out 92.2 % of 102) and the shares of
cells marked. Tried, not kept: the ray without the climb over every node, hidden or not: sample1
0.0153 0.042 0.551 -> 0.0163 0.042 1.179 (two nodes on the dome cut 1.1-1.3 mm by a ray that glare
made), sample3 0.0429 0.105 0.480 -> 0.0431 0.106 0.619, cells marked on crater 28.9 -> 37.4 %.
(y) Session 36 (6 December 2026: frames whose ink the displacement took below the base top are
no waterlines; see benches/meniscus.py), (v)'s renders, 77e6da4 -> this: sample1 0.0153 0.042
0.551 -> 0.0155 0.043 0.640, sample2 0.0170 0.052 0.165 -> 0.0211 0.066 0.134 (0.005 mm lower
all over: its upper levels solved a little lower), twin-peaks 0.0226 0.085 0.275 -> 0.0227 0.085
0.282; held out crater 0.0365 0.198 0.241 -> 0.0365 0.198 0.231; sample3, sample4, plateau, ring
and steep-front the same to the digit. Honest share: tuned 97.5 % of 1960 -> 97.5 % of 1964, held
out 92.2 % of 102 -> 96.0 % of 99. Over the targets: sample4 (all three).
(z) Session 38 (7 December 2026): the whole bench on fresh renders, the ink now falling away from
a camera fixed to the tank (main ed9a700; meniscus commissioned 2.506 mm / 0.17 deg / 0.98),
Ea / interior p99 / max mm, honest share of (cells over 0.1 mm):
    sample1    0.0116 0.041 0.187  83% of 6       sample2    0.0114 0.024 0.057   -  of 0
    sample3    0.0162 0.037 0.478 100% of 49      sample4    0.1842 0.319 1.754 100% of 1457
    twin-peaks 0.0202 0.085 0.272  42% of 19      plateau    0.0356 0.201 0.278  86% of 105
    ring       0.0370 0.182 0.449 100% of 157
  held out: crater 0.0370 0.202 0.223 100% of 98, steep-front 0.0111 0.067 0.137 0% of 3.
  Honest share: tuned 98.5 % of 1793, held out 97.0 % of 101. Over the targets: sample4 (all
  three), plateau's and crater's p99 by 0.001 and 0.002 mm. Session 38's edge nodes
  (surface/edges.py) leave all nine the same to the digit (no part here had a hole inside its
  outline).
(za) Session 39 (7 December 2026), (z)'s renders: the rays over hidden rims (surface/rimrays.py)
  leave all nine the same to the digit (Ea, p99, max). Sample 4's map has 1.8 mm² of material more
  than a node beyond its outline (1.3 before session 38's edge nodes): a row of nodes 0.34 mm past
  its y = 55 wall, 13.7-16 mm high; not looked into.
(zb) Session 40 (7 December 2026): fresh renders on another machine (meniscus commissioned 2.506
  mm / 0.17 deg / 0.97); main 77f42c0 gives each within 0.0003 mm of (z)'s Ea (sample4 0.1843
  0.319 1.756, plateau 0.0356 0.201 0.277, ring 0.0372 0.182 0.449; crater 0.0367 0.196 0.232
  100% of 96: its p99 passes on this render). Brackets beside rims put back (surface/flatfaces.py)
  leave all nine the same. A blank frame's noise no longer chooses the channel (vision/frames.py
  best_channel): the same channel as before in every one of these scans' frames, so all the same.
  (A trial run that read frames otherwise made the runner's refinement add frames to the kept
  sample2 scan, now 20 of its 60: 0.0102 0.022 0.087 from then on, on 77f42c0 as on this.)
  A flat face's nodes near their own frame's level curve bracketed too (24b01c1): plateau 0.0356
  0.201 0.277 86% of 105 -> 0.0334 0.133 0.277 70% of 44, the other eight the same. All parts
  but sample4 now meet all three targets; honest share tuned 98.4 % of 1739, held out 97.0 % of 99.
  Held out nuisances, sample 4 rendered with this preset less one thing (Ea / p99 / max mm):
  without wobble 0.1955 0.451 1.170, without ripple 0.1955 0.345 1.692, without both 0.2142
  0.483 1.188, the images of the physics preset (ripple, wobble, moving glare, JPEG and flicker
  off, this meniscus kept) 0.0962 0.274 0.668: its error is this meniscus on a small steep part,
  then the images, not the stage. Without glare and dust, before that fix, no frame showed a
  waterline (every frame read in blue, chosen from a blank frame's noise); after it 0.1332 0.183
  2.630. Sample 3 (e160c27) with 12 glare blobs at 255: 0.0164 0.030 0.517; 300 dust specks:
  0.0160 0.037 0.470; a 0.15 mm ripple: 0.0208 0.041 0.521; salt and pepper 1e-3: 0.0152 0.033
  0.459; 5 % flicker: 0.0160 0.036 0.502; 0.1 mm wobble (twice the issue's): 0.0563 0.130 0.512.

(zc) Session 44 (7 December 2026), held out: a finer plan (--step-mm 0.5, fresh renders, the
  (zb) camera and meniscus). On main 4dfb79e sample 3 came out at 0.0510 mm, three times its 1 mm
  figure: its far wall's chain of edges broke in five frames, those frames' rims were put back
  short, the grid and the footprint the displacement weighs grew by them (10208 mm^2 for
  10000) and every level below stood 0.27-0.41 mm low. Edges followed over 2 mm of level, the
  footprint and bounds from what two frames agree on (surface/perspective.py, lattice.py,
  slices.py): 0.5 mm steps sample3 0.0510 -> 0.0244 0.051 0.473, twin-peaks 0.0157 0.090 0.140
  (the same), sample4 0.3627 -> 0.3490 0.440 4.336. (zb)'s 1 mm renders: sample2 0.0102 ->
  0.0074, sample3 0.0162 -> 0.0143, crater 0.0367 -> 0.0366 (p99 0.194 -> 0.189), the others
  within 0.0001. Sample 4 at 0.5 mm steps is worse than at 1 mm (0.349 against 0.184): its flat
  corner at (46, 45.7), level in truth, is solved 2.2 mm high by the meniscus correction's free
  mode (surface/contact_lines.py); at 1 mm steps that corner comes out at once and its bracket
  holds it. Not fixed.
(zd) Session 45 (7 December 2026), held out by realisation: sample 4 rendered again at render
  seeds 2-5 (`--parts sample4:2,...`: the same part, plan, camera and meniscus file as (zb), only
  the noise, glare, dust and play drawn afresh), main 6f491d3. Ea / interior p99 / max mm:
  seed 1 (zb's render) 0.1842 0.319 1.756; seed 2 0.3195 0.385 3.124; seed 3 0.3407 0.423 5.066;
  seed 4 0.2470 0.499 3.445; seed 5 0.3250 0.637 2.838. Seed 1 is the best of five, not typical.
  Samples 1-3 and twin-peaks at seed 2 stay within all three targets (0.0116 0.034 0.168,
  0.0084 0.020 0.054, 0.0148 0.044 0.483, 0.0194 0.097 0.673). Sample 4's cells over 1 mm
  are in two places:
  - the flat corner at (46-48, 45-46.1), level in truth at 22.3 mm, solved 2.0-3.1 mm high
    (seeds 2, 3, 5: 112-126 cells, 0.08-0.10 mm of Ea). Glare over it in the frames above is
    not the cause (seed 4 has as much and holds). The cause, on seed 5: a few points of the
    y = 45 wall in the frames at 21, 20 and 19 mm (1-6 each, 0.05-0.09 mm off the neighbours'
    waterlines, more than the 0.03 mm wall tolerance: the play the registration leaves) stay
    level-curve points at the wall, a level or two below the corner. First exposure then
    finds no height for 176 of its 260 nodes (its polynomial leaves the bracket; seed 1: all
    247 placed at 22.24-22.37), the fit of the apparent surface there swings 20.4-23.5 with
    slopes up to 8, and the meniscus solve adds the rise that slope asks (+1.4 mm median).
    Tried, not kept: runs of points beside a wall, up to 10 points along the loop, within
    0.06 mm of a neighbour's waterline (never as far as an 86-degree face moves in the step),
    are wall too. Grown in every frame: seeds 1-5 0.1844 0.1975 0.1433 0.2383 0.2295, but the
    harsh ring 0.0372 -> 0.0550 (its hole's wall in the lowest frame, marked right at last,
    showed that the meniscus solve there stands 0.1-0.2 mm high: those 10 level-curve points
    had pulled it down). Not grown in the lowest frame: seeds 1-5 0.1845 0.1977 0.3349 0.2387
    0.2305; on the 21 kept bench scans (harsh and second ink) second-ink sample 3 0.0273 ->
    0.0255, sample 2 0.0122 -> 0.0114, harsh sample 3 0.0143 -> 0.0137, the ring unchanged,
    but second-ink sample 4 0.0493 -> 0.0501, stepped block 0.2447 -> 0.2556, steps 0.3252 ->
    0.3277. Only along the wall's own direction (15 degrees): seed 5 0.2282 but seed 2 0.3098,
    and the kept scans no better.
  - the summit along the y = 55 wall (x 49.4-52, true 37-38.6), 2.8-5.1 mm low (seeds 3, 4 and
    2: 18-25 cells). In seed 3 the sliver shows in frames 36-34 with a peak of 46-67 DN over a
    glare haze of 21-33, against the frame's threshold of 75 (the part's lit faces are ~240):
    it is first read at level 33 and the summit is extrapolated from there.
  Tried on these renders, not kept: (1) the renderer's own play taken out of every frame in
  place of the registration (an oracle): the meniscus-free render 0.1128 -> 0.0906, seed 1
  harsh 0.1842 -> 0.2150 (worse); the registration leaves 0.025 of 0.036 mm rms because from
  level 36 to 22 only the y = 45 and y = 55 walls are in view, which tell nothing about x. (2) The
  play from each frame's second difference to its neighbours (every point of a smooth face, not
  only walls): 0.027-0.031 mm rms left, no better. (3) The contact lines' bend taken from the
  seen (apparent) level curves everywhere instead of the solved top's: 0.1842 -> 0.2768, second
  ink 0.0493 -> 0.0840 (the renderer bends the meniscus by the top's level curve).

(ze) Session 46 (8 December 2026), (zd)'s summit: the top along the y = 55 wall is a face turned
  from the lamp, 84 grey once wide against a threshold of 76, and its sliver is blurred under
  that (peaks 58 at 36 mm, 73-75 at 35). The frames above the first to show the part are now
  also read with a split learned inside the part the lower frames show (vision/above.py), and a
  profile across the sliver is placed where it crosses that split (subpixel.refine_at). Seeds 2
  and 3 read the frames at 34 and 35 mm; cells of the top (true > 35 mm) over 1 mm 18 -> 5 and
  27 -> 7, all left in the row 0.15 mm from the wall. Ea / interior p99 / max: seed 1 0.1842
  0.319 1.758 (the same), seed 2 0.3091 0.386 3.126 (its max is at the corner), seed 3 0.3154
  0.423 2.588; seeds 4 and 5 unchanged (seed 4 learned a threshold of 29: its top is read).
  Crater and steep-front, samples 1-3 and twin-peaks at seed 2 and the 21 kept harsh and
  second-ink scans: unchanged to 0.0001. Read with that split only where the learned threshold
  found nothing: seed 2 read 34 mm with one threshold and 35 mm with the other, a blurred sliver
  reads a pixel wider at the lower one, and its top was extrapolated to 40.03 for 38.55 (0.3139).

    nice -n 10 .venv/bin/python benches/harsh.py --keep /tmp/harsh     # render once, re-process later
    nice -n 10 .venv/bin/python benches/harsh.py --parts sample1,twin-peaks
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from meniscus import bench_folder, commission, described, scan_part
from outline import spurious
from uncertainty import honesty

from appliance.sim import surfaces
from appliance.vision.refine import RESOLUTION_MM

PARTS = "sample1,sample2,sample3,sample4,twin-peaks,plateau,ring"
# shapes the uncertainty map was not tuned on, and sample 4 drawn afresh (render seeds 2 and 3:
# its seed-1 figures are the best of five, (zd))
HELD_OUT = "crater,steep-front,sample4:2,sample4:3"
TARGETS = {"Ea": 0.05, "p99": 0.2, "max": 1.0}


def measure(name, seed, tmp, camera, meniscus, refine_mm, step_mm=1.0):
    """-> (label, Ea, p99, max, honest share, cells over 0.1 mm, share marked) of one scan."""
    t0 = time.perf_counter()
    maps = []
    ea, p99, mx = scan_part(
        name,
        "harsh",
        tmp,
        camera,
        meniscus,
        step=step_mm,
        maps=maps,
        from_above=True,
        seed=seed,
        refine_mm=refine_mm,
    )
    share, big, marked = honesty(surfaces.get(name), maps[0])
    area, tallest = spurious(surfaces.get(name), maps[0])
    label = name if seed == 1 else f"{name}:{seed}"
    print(
        f"  {label:<14} Ea {ea:.4f} mm, interior p99 {p99:.3f} mm, max {mx:.3f} mm, "
        f"beyond the part {area:.1f} mm² (up to {tallest:.2f} mm), "
        f"{100 * share:.0f} % of {big} cells over 0.1 mm marked uncertain "
        f"({100 * marked:.1f} % of all marked) ({time.perf_counter() - t0:.0f} s)",
        flush=True,
    )
    return label, ea, p99, mx, share, big, marked


def parsed(spec):
    """'sample3:2,crater' -> [('sample3', 2), ('crater', 1)] (render seed 1 unless given)."""
    out = []
    for item in filter(None, spec.split(",")):
        name, _, seed = item.partition(":")
        out.append((name, int(seed) if seed else 1))
    return out


def summary(title, rows, targets=True):
    print(f"\n{title}")
    print(f"  {'part':<14} {'Ea':>7} {'p99 in':>7} {'max':>7} {'honest':>7} {'marked':>7}")
    for label, ea, p99, mx, share, _big, marked in rows:
        over = [k for k, v in zip(TARGETS, (ea, p99, mx)) if targets and v > TARGETS[k]]
        print(
            f"  {label:<14} {ea:7.4f} {p99:7.3f} {mx:7.3f} {100 * share:6.0f}% {100 * marked:6.1f}%"
            + (f"  over: {', '.join(over)}" if over else "")
        )
    big = sum(r[5] for r in rows)
    if rows:
        print(
            f"  all: {100 * sum(r[4] * r[5] for r in rows) / max(big, 1):.1f} % of {big} cells off by more than "
            f"0.1 mm marked uncertain (target >= 80 %); {100 * sum(r[6] for r in rows) / len(rows):.1f} % of "
            "the cells marked (mean over the parts)"
        )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default=PARTS)
    ap.add_argument(
        "--heldout",
        default=HELD_OUT,
        help="NAME[:SEED],... scans the uncertainty map was not tuned on (render seed 1 unless given); "
        "'' for none",
    )
    ap.add_argument(
        "--keep",
        default=None,
        metavar="DIR",
        help="render into DIR and reuse what is there (renders take minutes a part)",
    )
    ap.add_argument(
        "--refine-mm",
        type=float,
        default=RESOLUTION_MM,
        help="bisect the steps in which a face came out at once to this, as the daemon's runner does "
        "(0: only the plan's levels)",
    )
    ap.add_argument(
        "--step-mm",
        type=float,
        default=1.0,
        help="the plan's level step (renders kept with --keep are of the step they were made at: "
        "give another folder for another step)",
    )
    args = ap.parse_args()
    with bench_folder(args.keep, "harsh-bench-") as (tmp, camera):
        t0 = time.perf_counter()
        meniscus, doc = commission(tmp, "harsh", camera)
        print(
            f"harsh: meniscus commissioned from the reference ball ({time.perf_counter() - t0:.0f} s): "
            + described(doc),
            flush=True,
        )
        rows = [
            measure(name, seed, tmp, camera, meniscus, args.refine_mm, args.step_mm)
            for name, seed in parsed(args.parts)
        ]
        held = [
            measure(name, seed, tmp, camera, meniscus, args.refine_mm, args.step_mm)
            for name, seed in parsed(args.heldout)
        ]
    summary("summary, harsh preset (mm); targets Ea <= 0.05, p99 <= 0.2, max <= 1", rows)
    if held:
        summary("held out (scans and shapes the uncertainty map was not tuned on)", held, targets=False)


if __name__ == "__main__":
    main()
