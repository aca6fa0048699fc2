"""Surface room bench: speed/memory of the height map, and accuracy on ideal waterlines.

    .venv/bin/python benches/surface.py            # speed (0.1 mm grid, 80 levels) + ideal accuracy
    .venv/bin/python benches/surface.py --quick    # coarser waterlines, samples 1 and 4 only
    .venv/bin/python benches/surface.py --only speed|ideal

Speed: a 100 x 100 mm part (sample 1) seen at 80 levels, waterlines as dense
as 2048 x 1536 frames give them (0.08 mm/px), reconstructed on a 0.1 mm grid
(1001 x 1001), one thread; median of repeats; peak memory by tracemalloc
(numpy reports its buffers to it) during the reconstruction.
Ideal: samples 1-4 at 1 mm steps on the dissertation's 50 x 50 grid, our fit
beside the dissertation's methods on the same waterlines and its tables.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from appliance.sim import surfaces
from appliance.sim.ideal import ideal_waterlines
from appliance.surface.reconstruct import GridSpec, ReconstructOptions, reconstruct
from appliance.surface.seedtables import TABLES
from appliance.surface.stats import seed_statistics


def stats_for(surface, hm):
    X, Y = hm.grid()
    zt = np.where(surface.inside(X, Y), surface.to_dissertation(surface.height(X, Y)), np.nan)
    return seed_statistics(zt, surface.to_dissertation(hm.z), surface.table_normaliser)


def speed(quick):
    import cv2

    cv2.setNumThreads(1)
    s = surfaces.get("sample1")
    levels = np.linspace(s.z_max + 0.2, 0.5, 80)
    res = 0.25 if quick else 0.08
    t0 = time.perf_counter()
    lines = ideal_waterlines(s, levels, res)
    print(
        f"speed: {len(lines)} levels, {sum(len(w.points) for w in lines)} waterline points "
        f"(at {res} mm), made in {time.perf_counter() - t0:.1f} s"
    )
    grid = GridSpec(s.bounds, spacing_mm=0.1)
    times = []
    for _ in range(1 if quick else 3):
        t = time.perf_counter()
        rec = reconstruct(lines, grid)
        times.append(time.perf_counter() - t)
    tracemalloc.start()
    rec = reconstruct(lines, grid)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    st = stats_for(s, rec.heightmap)
    print(
        f"  0.1 mm grid {rec.heightmap.z.shape[1]} x {rec.heightmap.z.shape[0]}: median {statistics.median(times):.2f} s "
        f"(runs {', '.join(f'{x:.2f}' for x in times)}), peak traced memory {peak / 2**20:.0f} MB, "
        f"Ea {st['Ea']:.4f} mm"
    )


def ideal(quick):
    names = ("sample1", "sample4") if quick else ("sample1", "sample2", "sample3", "sample4")
    print("\nideal waterlines, 1 mm steps, 50 x 50 grid: Ea / sigma / max (mm), degree of matching %")
    print(
        f"  {'sample':<8} {'method':<10} {'Ea':>8} {'sigma':>8} {'max':>8} {'DoM %':>9}   diss best Ea   x better"
    )
    for name in names:
        s = surfaces.get(name)
        from appliance.sim.scanrender import scan_levels

        lv = scan_levels(s, 1.0)
        res = (0.2 if quick else 0.1) * (s.bounds[1] - s.bounds[0]) / 100
        lines = ideal_waterlines(s, lv, res)
        g = GridSpec(s.bounds, n=(50, 50))
        diss_best = min(v[0] for v in TABLES[name].values())
        for m in ("fit", "nearest", "lsq3"):
            rec = reconstruct(lines, g, ReconstructOptions(method=m))
            st = stats_for(s, rec.heightmap)
            extra = f"   {diss_best:8.4f}   {diss_best / st['Ea']:8.1f}" if m == "fit" else ""
            print(
                f"  {name:<8} {m:<10} {st['Ea']:8.4f} {st['sigma']:8.4f} {st['max_error']:8.4f} "
                f"{st['matching']:9.4f}{extra}"
            )


def rendered(quick, samples, preset, keep=None):
    """Render (renderer team), extract (vision team), reconstruct with and without corrections."""
    import json
    import tempfile

    from appliance.scanfile import load_scan, read_frame
    from appliance.sim.rig import Rig
    from appliance.sim.scanrender import render_scan
    from appliance.surface.meniscus import MeniscusModel
    from appliance.vision.pipeline import WaterlineExtractor

    print(f"\nrendered frames ({preset} effects), 1 mm steps, 50 x 50 grid: Ea / sigma / DoM %")
    for name in samples:
        s = surfaces.get(name)
        with tempfile.TemporaryDirectory(prefix="surface-bench-") as tmp:
            tmp = keep or tmp  # --keep DIR: render once, re-process later
            folder = Path(tmp) / f"{name}-{preset}"
            t0 = time.perf_counter()
            if not (folder / "scan.json").is_file():
                render_scan(s, folder, step_mm=1.0, rig=Rig(), effects=preset, seed=1)
            t1 = time.perf_counter()
            scan = load_scan(folder)
            truth = json.loads((Path(tmp) / f"{name}-{preset}.truth.json").read_text())
            ex = WaterlineExtractor(scan.camera, no_part="empty")
            lines = []
            for ref in sorted(scan.frames, key=lambda f: -f.level_mm):
                try:
                    lines.append(ex.extract(read_frame(scan, ref), ref.level_mm))
                except Exception as e:
                    print(f"  {name}: frame at {ref.level_mm} failed: {e}")
            t2 = time.perf_counter()
            tank = scan.extra.get("tank", {}).get("inner_area_mm2", 22500.0)
            men = truth["meniscus"]
            model = MeniscusModel(
                men["capillary_length_mm"],
                np.radians(men["contact_angle_deg"]),
                scan.camera.centre_xy(),
                scan.camera.height_mm,
            )
            g = GridSpec(s.bounds, n=(50, 50))
            print(f"  {name}: render {t1 - t0:.0f} s, extract {t2 - t1:.0f} s")
            for label, opt in (
                ("no corrections", ReconstructOptions()),
                ("displacement", ReconstructOptions(tank_area_mm2=tank)),
                ("displ.+meniscus", ReconstructOptions(tank_area_mm2=tank, meniscus=model)),
                ("nearest (diss.)", ReconstructOptions(method="nearest", tank_area_mm2=tank)),
                ("lsq3 (diss.)", ReconstructOptions(method="lsq3", tank_area_mm2=tank)),
            ):
                st = stats_for(s, reconstruct(lines, g, opt).heightmap)
                print(f"    {label:<18} {st['Ea']:8.4f} {st['sigma']:8.4f} {st['matching']:9.4f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("speed", "ideal", "rendered"))
    ap.add_argument("--samples", default="sample1,sample2,sample3,sample4")
    ap.add_argument("--effects", default="physics")
    ap.add_argument("--keep", help="folder to keep rendered scans in (and reuse)")
    a = ap.parse_args()
    if a.only == "rendered":
        rendered(a.quick, a.samples.split(","), a.effects, a.keep)
        return
    if a.only in (None, "speed"):
        speed(a.quick)
    if a.only in (None, "ideal"):
        ideal(a.quick)


if __name__ == "__main__":
    main()
