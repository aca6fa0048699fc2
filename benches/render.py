"""Milliseconds per 2048 x 1536 frame of the virtual bench, one thread.

    .venv/bin/python benches/render.py [--quick]

Prints (CPU ms of this process, so a busy machine does not inflate it), per part and effects preset, the median time of render_frame over
levels spread from the part's top to its base (the frames the seed-table
bench renders), and the PNG write time (scanfile.write_frame's encoder).
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2
import numpy as np

from appliance.sim import surfaces as S
from appliance.sim.render import PRESETS, render_frame, surface_grid
from appliance.sim.rig import Rig, pixel_map


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--parts", default="sample1,sample2,sample3,sample4")
    a = ap.parse_args()
    cv2.setNumThreads(1)
    rig = Rig()
    t = time.perf_counter()
    pixel_map(rig, False)
    pixel_map(rig, True)
    print(f"per-rig pixel maps (once): {1000 * (time.perf_counter() - t):.0f} ms")
    nlev = 4 if a.quick else 8
    overall = {}
    for name in a.parts.split(","):
        s = S.get(name)
        t = time.perf_counter()
        g = surface_grid(s)
        print(f"{name}: part grids (once) {1000 * (time.perf_counter() - t):.0f} ms")
        levels = np.linspace(g.z_max - 0.5, 1.0, nlev)
        for preset in ("clean", "realistic"):
            times = []
            for i, lv in enumerate(levels):
                # CPU time of this process: the bench box is shared while we build,
                # and wall time then counts other people's work
                t = time.process_time()
                img = render_frame(s, float(lv), rig, PRESETS[preset], np.random.default_rng(i))
                times.append(1000 * (time.process_time() - t))
            overall.setdefault(preset, []).extend(times)
            print(f"  {preset:9s} median {statistics.median(times):6.0f} ms  max {max(times):6.0f} ms")
    t = time.perf_counter()
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    print(f"PNG encode (level 1): {1000 * (time.perf_counter() - t):.0f} ms, {len(buf) / 1e6:.2f} MB")
    for preset, times in overall.items():
        print(
            f"ALL {preset:9s} median {statistics.median(times):6.0f} ms  mean {statistics.mean(times):6.0f} ms "
            f"max {max(times):6.0f} ms per 2048x1536 frame"
        )


if __name__ == "__main__":
    main()
