"""inkslice scan --sim SURFACE -o SCAN: one scan on the simulated bench through the daemon's runner."""

import shutil
import sys
import tempfile
from pathlib import Path

from ..errors import InkSliceError, SettingError

NAME = "scan"
ORDER = 15
HELP = "run one scan on the simulated bench (no web) and copy the scan folder and outputs to -o"


def add_arguments(p):
    p.add_argument("--sim", required=True, metavar="SURFACE", help="the part to scan (a known surface name)")
    p.add_argument("-o", "--out", required=True, help="folder for the scan (scan.json, frames/) and outputs")
    p.add_argument(
        "--bench",
        choices=("fake", "simavr"),
        default="simavr",
        help="simavr: the real firmware under simavr (default); fake: in-memory stage",
    )
    p.add_argument("--frame", default="640x480", help="frame size WxH (default 640x480)")
    p.add_argument(
        "--top",
        type=float,
        default=None,
        help="first level, mm (default: the daemon's; the scan starts higher when the part shows)",
    )
    p.add_argument("--bottom", type=float, default=0.0, help="last level, mm (default 0: the base top)")
    p.add_argument("--step", type=float, default=1.0, help="level step, mm (default 1)")
    p.add_argument("--adaptive", action="store_true", help="adaptive step between --step-min and --step-max")
    p.add_argument("--step-min", type=float, default=0.25)
    p.add_argument("--step-max", type=float, default=2.0)
    p.add_argument("--settle", type=float, default=0.0, help="settle time after each move, s (default 0)")


def run(args):
    from ..daemon.processing import in_process
    from ..daemon.service import BenchService
    from ..sim import surfaces
    from ..sim.fakes import FakeBench, SimulatedBenchFactory, small_rig
    from .daemon import frame_size

    surface = surfaces.get(args.sim)
    out = Path(args.out)
    if out.exists() and any(out.iterdir()):
        raise SettingError("-o", f"{out} exists and is not empty")
    rig = small_rig(*frame_size(args.frame))
    factory = (
        FakeBench(surface.name, rig) if args.bench == "fake" else SimulatedBenchFactory(surface.name, rig)
    )
    params = {
        "name": f"sim {surface.name}",
        "surface": surface.name,
        "levels_from_mm": args.bottom,
        "level_step_mm": args.step,
        "settle_s": args.settle,
        "step_mode": "adaptive" if args.adaptive else "fixed",
        "step_min_mm": args.step_min,
        "step_max_mm": args.step_max,
    }
    if args.top is not None:
        params["levels_to_mm"] = args.top
    with tempfile.TemporaryDirectory(prefix="inkslice-scan-") as data:
        service = BenchService(data, factory, processor=factory.processor(in_process))
        try:
            job_id = service.start_scan(params)
            for st in service.subscribe(timeout=24 * 3600):
                if st["state"] in ("scanning", "processing"):
                    print(
                        f"\r{st['state']}: {st['levels_done']}/{st['levels_total']} {st['message']:<30}",
                        end="",
                        file=sys.stderr,
                    )
                if st["state"] in ("done", "failed", "cancelled") and st["job_id"] == job_id:
                    break
            print(file=sys.stderr)
            job = service.job(job_id)
        finally:
            service.close()
            factory.close()
        if job["status"] != "done":
            raise InkSliceError(f"scan {job_id}", job["reason"])
        shutil.copytree(Path(data) / "jobs" / job_id, out, dirs_exist_ok=True)
    for name in job["outputs"]:
        print(out / name)
    print(out / "scan")
    return 0
