"""Commissioning a simulated box through the daemon, then scanning a part with it: the figures.

The bench: the stepper firmware under simavr, the renderer's camera at full size (2048 x
1536) with an effects preset (physics: noise, blur, glare, dust, lens distortion, the ink's
displacement and its meniscus), and a true level zero the daemon's setting does not know.
The daemon (BenchService) commissions it through its own API, as the phone would: level
zero measured with the stage and the camera, the camera from views of the printed board,
the tank entered, the meniscus from a scan of a 25.4 mm ball. Then it scans the part, once
before commissioning (level zero entered right, nothing else: the bench's own camera
model, no tank, no meniscus) and once after, and prints Ea against the part's truth.

    .venv/bin/python benches/commissioning.py                     # sample3, physics
    .venv/bin/python benches/commissioning.py --sample sample1 --views 6
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from appliance.daemon.processing import in_process
from appliance.daemon.service import BenchService
from appliance.outputs import read_heightmap_csv
from appliance.sim import surfaces
from appliance.sim.fakes import SimulatedBenchFactory
from appliance.sim.levels import ink_margins
from appliance.sim.render import effects_preset
from appliance.sim.rig import Rig
from appliance.surface.stats import seed_statistics

TRUE_LEVEL_ZERO = 57.3


def wait(svc, job_id, timeout=3600):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        job = svc.job(job_id)
        if job["status"] in ("done", "failed", "cancelled") and svc.state()["state"] in (
            "done",
            "failed",
            "cancelled",
        ):
            return job
        time.sleep(0.5)
    raise SystemExit(f"job {job_id} did not finish in {timeout} s")


def scan_params(sample, step, effects):
    """The dissertation's levels (benches/seed_table.py): from just below the top down past the
    top's lowest point, by the wall's meniscus rise more with a meniscus."""
    part = surfaces.get(sample)
    below, _ = ink_margins(effects_preset(effects))
    top = math.floor(part.z_max / step) * step
    bottom = math.floor((part.z_min_top - step - below) / step) * step
    return {
        "name": sample,
        "levels_to_mm": top,
        "levels_from_mm": max(bottom, 0.5),
        "level_step_mm": step,
        "settle_s": 0.0,
    }


def statistics(svc, job, sample):
    """The job's height map against the part's truth (the daemon itself knows no truth)."""
    part = surfaces.get(sample)
    hm = read_heightmap_csv(svc.job_file(job["id"], "heightmap.csv"))
    X, Y = hm.grid()
    z_true = np.where(part.inside(X, Y), part.to_dissertation(part.height(X, Y)), np.nan)
    norm = part.table_normaliser or float(np.nanmax(np.abs(z_true)))
    return seed_statistics(z_true, part.to_dissertation(hm.z), norm)


def scan(svc, params, label, sample):
    t0 = time.monotonic()
    job = wait(svc, svc.start_scan(params))
    if job["status"] != "done":
        raise SystemExit(f"{label}: the scan {job['status']}: {job['reason']}")
    report = json.loads(svc.job_file(job["id"], "report.json").read_text())
    s = statistics(svc, job, sample)
    print(
        f"  {label:<34} Ea {s['Ea']:.4f} mm, sigma {s['sigma']:.4f}, max {s['max_error']:.3f} mm, "
        f"matching {s['matching']:.3f} % ({job['levels_done']} frames, {time.monotonic() - t0:.0f} s)"
    )
    for w in report["calibration"]["warnings"]:
        print(f"    warning: {w}")
    return s


def commission(svc, views, diameter):
    t0 = time.monotonic()
    svc.commission("level_zero", "start")
    c = svc.commission("level_zero", "measure")
    lz = c["active"]["detected"]["level_at_home_mm"]
    svc.commission("level_zero", "accept")
    print(
        f"  level zero: {lz:.4f} mm (true {TRUE_LEVEL_ZERO}: {abs(lz - TRUE_LEVEL_ZERO) * 1000:.1f} um off), "
        f"{time.monotonic() - t0:.0f} s"
    )
    t0 = time.monotonic()
    svc.commission("camera", "start")
    for _ in range(views):
        svc.commission("camera", "view")
    cam = svc.commission("camera", "plane")["active"]["detected"]
    svc.commission("camera", "accept")
    print(f"  camera: {cam} ({time.monotonic() - t0:.0f} s)")
    svc.commission("tank", "enter", {"width_mm": 150, "depth_mm": 150})
    t0 = time.monotonic()
    svc.commission("meniscus", "start", {"diameter_mm": diameter})
    job = wait(svc, svc.commission("meniscus", "scan")["active"]["job_id"])
    c = svc.commissioning()
    if c["active"]["stage"] != "check":
        raise SystemExit(f"meniscus: {c['active']}")
    c = svc.commission("meniscus", "accept")
    men = next(s for s in c["steps"] if s["id"] == "meniscus")["result"]
    print(
        f"  meniscus: capillary length {men['capillary_length_mm']:.3f} mm, contact angle "
        f"{men['contact_angle_deg']:.2f} deg; the {diameter:g} mm ball measured to "
        f"{men['reference']['mean_abs_error_mm']:.4f} mm (max {men['reference']['max_error_mm']:.3f}) "
        f"({job['levels_done']} frames, {time.monotonic() - t0:.0f} s)"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sample", default="sample3")
    ap.add_argument("--effects", default="physics")
    ap.add_argument("--step", type=float, default=1.0)
    ap.add_argument("--views", type=int, default=8, help="tilted board views for the lens (default 8)")
    ap.add_argument("--diameter", type=float, default=25.4, help="the reference ball, mm")
    ap.add_argument("--skip-before", action="store_true", help="only the scan after commissioning")
    args = ap.parse_args()
    e = effects_preset(args.effects)
    print(
        f"{args.sample} on the simulated bench (simavr, 2048 x 1536, effects {args.effects}: capillary length "
        f"{e.capillary_length_mm} mm, contact angle {e.contact_angle_deg} deg, tank 150 x 150 mm), "
        f"level step {args.step:g} mm"
    )
    factory = SimulatedBenchFactory(
        args.sample, Rig(), effects=args.effects, level_at_home_mm=TRUE_LEVEL_ZERO
    )
    with tempfile.TemporaryDirectory(prefix="commissioning-") as tmp:
        svc = BenchService(Path(tmp) / "data", factory, processor=in_process)
        try:
            params = scan_params(args.sample, args.step, args.effects)
            if not args.skip_before:
                # level zero entered right: what is left out is the camera, tank and meniscus
                before = scan(
                    svc, {**params, "level_at_home_mm": TRUE_LEVEL_ZERO}, "before commissioning", args.sample
                )
            print("commissioning:")
            commission(svc, args.views, args.diameter)
            after = scan(svc, params, "after commissioning", args.sample)
            if not args.skip_before:
                print(
                    f"=> Ea {before['Ea']:.4f} mm before, {after['Ea']:.4f} mm after commissioning "
                    f"({before['Ea'] / after['Ea']:.1f}x lower)"
                )
        finally:
            svc.close()
            factory.close()


if __name__ == "__main__":
    main()
