"""The harsh bench: does a waterline survive what a bad day at the bench throws at it?

The `harsh` effects preset (sim/render.py) puts on every frame glare that drifts, jitters,
flickers and vanishes from frame to frame, drifting dust and bubbles, salt and pepper, JPEG
q85, 1.5 % lamp flicker, up to 0.05 mm of lateral stage wobble, a rippling surface, and a
meniscus that is not the first model's. As a user would, the bench calibrates the camera
from rendered chessboards and commissions the meniscus from a harsh scan of the reference
ball (benches/meniscus.py's commission), then scans each part and processes it.

Per part it prints Ea, the interior's 99th percentile (nodes more than 3 mm inside the
outline) and the largest error, in mm, against the part's truth. Targets (issue 18):
Ea <= 0.05 mm, interior p99 <= 0.2 mm, max <= 1 mm. And the uncertainty map's honesty: of
the cells off by more than 0.1 mm, the share it marks uncertain (uncertainty_mm > 0.1; target
>= 80 %), beside the share of all cells it marks (benches/uncertainty.py).

Measured (2 December 2026, 1 mm steps; meniscus commissioned 2.507 mm / 0.26 deg / weight 0.95
against the renderer's 2.5 mm / 0 / curved), Ea / interior p99 / max in mm, before the
monotone-exposure reading of the waterlines -> with it:
    sample1     0.0140 0.039 0.249 -> 0.0139 0.039 0.248
    sample2     0.0289 0.072 1.097 -> 0.0255 0.068 0.322   (its top's first sliver, 38 mm, now read)
    sample3     0.0263 0.196 0.466 -> 0.0260 0.196 0.466
    sample4     0.5122 0.563 5.009 -> 0.4962 0.582 3.225   (its corner's top shows 4 frames as a
                                                           faint shaded speck; one is now read)
    twin-peaks  0.2561 0.937 1.321 -> 0.2554 0.933 1.314   (flats, slope < 0.05: Ea 0.78; walls)
    plateau     2.3585 4.862 5.123 -> 2.3567 4.862 5.123   (flat top at 25 mm, the scan's first
    ring        0.1334 0.974 1.412 -> 0.1325 0.974 1.412    frame one step below: extrapolated)
What is left over is not glare: the waterlines of these scans are all but identical with and
without the rule (the colour test already takes this glare for ink); it is what a top or a
flat does between two levels and above the first frame.

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

from meniscus import bench_folder, commission, described, scan_part  # noqa: E402
from uncertainty import honesty                            # noqa: E402
from appliance.sim import surfaces                          # noqa: E402
from appliance.vision.refine import RESOLUTION_MM           # noqa: E402

PARTS = "sample1,sample2,sample3,sample4,twin-peaks,plateau,ring"
HELD_OUT = "crater,steep-front"    # shapes the uncertainty map was not tuned on
TARGETS = {"Ea": 0.05, "p99": 0.2, "max": 1.0}


def measure(name, seed, tmp, camera, meniscus, refine_mm):
    """-> (label, Ea, p99, max, honest share, cells over 0.1 mm, share marked) of one scan."""
    t0 = time.perf_counter()
    maps = []
    ea, p99, mx = scan_part(name, "harsh", tmp, camera, meniscus, maps=maps, from_above=True, seed=seed,
                            refine_mm=refine_mm)
    share, big, marked = honesty(surfaces.get(name), maps[0])
    label = name if seed == 1 else f"{name}:{seed}"
    print(f"  {label:<14} Ea {ea:.4f} mm, interior p99 {p99:.3f} mm, max {mx:.3f} mm, "
          f"{100 * share:.0f} % of {big} cells over 0.1 mm marked uncertain "
          f"({100 * marked:.1f} % of all marked) ({time.perf_counter() - t0:.0f} s)", flush=True)
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
    for label, ea, p99, mx, share, big, marked in rows:
        over = [k for k, v in zip(TARGETS, (ea, p99, mx)) if targets and v > TARGETS[k]]
        print(f"  {label:<14} {ea:7.4f} {p99:7.3f} {mx:7.3f} {100 * share:6.0f}% {100 * marked:6.1f}%"
              + (f"  over: {', '.join(over)}" if over else ""))
    big = sum(r[5] for r in rows)
    if rows:
        print(f"  all: {100 * sum(r[4] * r[5] for r in rows) / max(big, 1):.1f} % of {big} cells off by more than "
              f"0.1 mm marked uncertain (target >= 80 %); {100 * sum(r[6] for r in rows) / len(rows):.1f} % of "
              "the cells marked (mean over the parts)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default=PARTS)
    ap.add_argument("--heldout", default=HELD_OUT,
                    help="NAME[:SEED],... scans the uncertainty map was not tuned on (render seed 1 unless given); "
                         "'' for none")
    ap.add_argument("--keep", default=None, metavar="DIR",
                    help="render into DIR and reuse what is there (renders take minutes a part)")
    ap.add_argument("--refine-mm", type=float, default=RESOLUTION_MM,
                    help="bisect the steps in which a face came out at once to this, as the daemon's runner does "
                         "(0: only the plan's levels)")
    args = ap.parse_args()
    with bench_folder(args.keep, "harsh-bench-") as (tmp, camera):
        t0 = time.perf_counter()
        meniscus, doc = commission(tmp, "harsh", camera)
        print(f"harsh: meniscus commissioned from the reference ball ({time.perf_counter() - t0:.0f} s): "
              + described(doc),
              flush=True)
        rows = [measure(name, seed, tmp, camera, meniscus, args.refine_mm) for name, seed in parsed(args.parts)]
        held = [measure(name, seed, tmp, camera, meniscus, args.refine_mm) for name, seed in parsed(args.heldout)]
    summary("summary, harsh preset (mm); targets Ea <= 0.05, p99 <= 0.2, max <= 1", rows)
    if held:
        summary("held out (scans and shapes the uncertainty map was not tuned on)", held, targets=False)


if __name__ == "__main__":
    main()
