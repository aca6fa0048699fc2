"""The held-out pocket bench: a part whose top holds ink.

A pocket in the part's top cannot drain as the base rises: once the free surface is below
the pocket's rim, the pocket stays full to its spill height and its floor is never seen
(sim/pockets.py draws this when Effects.trapped_ink is on). None of our presets draws it,
and nothing in processing was made with it in mind: this bench is what a user's bowl, mould
cavity or spoon meets. The crater's bowl (its ridge crests at 22 mm all round, the floor at
5.1 mm) holds ink to 21.9 mm from the frame at 22 mm down.

What a user needs from the box here, in this order: no program that cuts into the pocket's
unseen floor; a report that says where and why; a scan that still yields a program for the
rest. The bench prints what processing did (refused, and why; or Ea / interior p99 / max
against the part's truth, in mm, and the error inside the pool's outline apart).

Measured (5 December 2026, main 1b6ba2d + the held-ink renderer, second ink, 1 mm steps from
above, the camera calibrated from rendered boards and the meniscus commissioned on the plain
ball): the crater is REFUSED, no program: "level 6 mm: shows 4334 mm² of the part, less than
the 5454 mm² at 7 mm above it: the part only emerges as the ink drops, so the frames
contradict their levels". The message names the wrong cause. The vision's loops show why:
the pool (1220 mm², the same in every frame) is a hole in the frames from 22 to 9 mm, read
ever smaller (1105 mm² at 22, 1016 at 13, 110 at 9), with none at 8 and 7 mm (a disc with no
hole), and back at 6 and 5 mm (1235-1247 mm²); why the vision loses it is not looked into
yet. What would close it: a hole whose outline stays put in the image while the level drops
is a contact line at a fixed height, not a waterline; below that height the pocket is
unseen, and the map there is at most the pool's surface (the program leaves it uncut, and
the report and the G-code header name it). Until then the operator's guide asks for such
pockets to be filled or drained before a scan.

    nice -n 10 .venv/bin/python benches/pockets.py --keep /tmp/pockets
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from meniscus import bench_folder, commission, errors
from seed_table import use_camera

from appliance import process as proc
from appliance.errors import InkSliceError
from appliance.sim import surfaces
from appliance.sim.levels import sculpture_levels
from appliance.sim.pockets import pool_level
from appliance.sim.render import effects_preset
from appliance.sim.scanrender import render_scan


def scan_with_pools(name, model, tmp, camera, meniscus, step=1.0):
    """-> (outcome line, Ea, p99, max, Ea inside the pools) of one scan whose pockets hold ink."""
    surface = surfaces.get(name)
    folder = tmp / f"{name}-{model}-held"
    if not (folder / "scan.json").is_file():
        effects = replace(effects_preset(model), trapped_ink=True)
        render_scan(
            surface,
            folder,
            levels=sculpture_levels(surface, step, 0.0, True),
            effects=effects,
            seed=1,
            workers=2,
        )
        use_camera(folder, camera)
    try:
        job = proc.process(folder, meniscus=meniscus)
    except InkSliceError as e:
        return f"refused: {e}", None
    hm = job.heightmap
    X, Y = hm.grid()
    pool = np.isfinite(pool_level(surface, X, Y)) & surface.inside(X, Y)
    err = np.abs(hm.z - surface.height(X, Y))
    in_pool = float(np.nanmean(err[pool])) if pool.any() else float("nan")
    return "processed", (*errors(surface, hm), in_pool)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="physics2")
    ap.add_argument("--parts", default="crater")
    ap.add_argument("--keep", default=None, metavar="DIR", help="render into DIR and reuse what is there")
    args = ap.parse_args()
    with bench_folder(args.keep, "pockets-bench-") as (tmp, camera):
        for model in args.models.split(","):
            meniscus, _ = commission(tmp, model, camera)
            for name in args.parts.split(","):
                t0 = time.perf_counter()
                outcome, figures = scan_with_pools(name, model, tmp, camera, meniscus)
                took = f"({time.perf_counter() - t0:.0f} s)"
                if figures is None:
                    print(f"  {model} {name}: {outcome} {took}", flush=True)
                else:
                    ea, p99, mx, pool = figures
                    print(
                        f"  {model} {name}: Ea {ea:.4f} mm, interior p99 {p99:.3f} mm, max {mx:.3f} mm, "
                        f"Ea inside the pools {pool:.3f} mm {took}",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
