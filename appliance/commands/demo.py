"""inkslice demo: a scan of a dissertation sample on the virtual bench, processed end to end."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..errors import SettingError
from ._flags import add_web_address

NAME = "demo"
ORDER = 10
HELP = "render a scan of a sample on the virtual bench, process it, print the statistics table"


def add_arguments(p):
    p.add_argument("--sample", default="sample3", help="known part to scan (default sample3)")
    p.add_argument("--step", type=float, default=1.0, help="level step in mm (default 1)")
    p.add_argument("--effects", default="realistic", help="virtual bench effects preset (default realistic)")
    p.add_argument("--out", default="demo-out", help="output folder (default ./demo-out)")
    p.add_argument(
        "--serve",
        action="store_true",
        help="then run the whole appliance on the simulated bench (firmware under simavr, "
        "virtual camera, daemon, web UI) until Ctrl-C",
    )
    p.add_argument("--serve-only", action="store_true", help="skip the table; only run the appliance")
    add_web_address(
        p,
        "127.0.0.1",
        "address the web UI listens on for --serve (default 127.0.0.1, this machine only; "
        "0.0.0.0 lets a phone on the same network open it: `make demo HOST=0.0.0.0`)",
        "web UI port for --serve (default 8080)",
    )
    p.add_argument("--part", default="sphere", help="the part on the simulated bench for --serve")


TABLE_KEY = {
    "seed:captured": "captured",
    "seed:spline": "spline",
    "seed:nearest": "nearest",
    "seed:lsq3": "lsq",
}


def print_table(job, out=sys.stdout):
    """Our statistics per method, with the dissertation's printed figures beside its methods."""
    from ..process import label
    from ..surface.seedtables import TABLES

    ref_of = TABLES.get(job.truth, {})
    print(
        f"\n{'method':<40} {'max mm':>8} {'Ea mm':>8} {'sigma':>8} {'Ep %':>8} {'match %':>9}"
        f"  | dissertation Ea / sigma / Ep",
        file=out,
    )
    for k, s in job.stats.items():
        ref = ref_of.get(TABLE_KEY.get(k, ""))
        tail = f"  | {ref[0]:.4f} / {ref[1]:.4g} / {ref[2]:.4f}" if ref else ""
        print(
            f"{label(k):<40} {s['max_error']:8.4f} {s['Ea']:8.4f} {s['sigma']:8.4f} "
            f"{s['Ep_table']:8.4f} {s['matching']:9.4f}{tail}",
            file=out,
        )


def check_gcode(path):
    """Run LinuxCNC's standalone interpreter over a program; its canonical output is discarded."""
    rs274 = shutil.which("rs274")
    if not rs274:
        return "not checked (LinuxCNC's rs274 is not installed)"
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run(
            [rs274, "-g", str(path), str(Path(tmp) / "canon.txt")],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
        )
    if r.returncode == 0:
        return "accepted by LinuxCNC's rs274 -g"
    return f"REJECTED by rs274 (exit {r.returncode}): {r.stderr.strip()[:200]}"


def serve_appliance(out: Path, part: str, port: int, host: str = "127.0.0.1"):
    """The whole appliance on this machine: the AVR firmware under simavr driven by the real
    stage driver, the virtual camera watching where the simulated stage really is, the
    daemon, and the web UI on loopback. Runs until interrupted."""
    from ..daemon.processing import child_process
    from ..daemon.service import BenchService
    from ..sim import surfaces
    from ..sim.fakes import SimulatedBenchFactory, small_rig
    from ..web.server import serve

    surfaces.get(part)
    data = out / "appliance"
    data.mkdir(parents=True, exist_ok=True)
    print(
        f"\nStarting the appliance on the simulated bench (firmware under simavr, part '{part}', "
        f"data in {data}) ...",
        flush=True,
    )
    factory = SimulatedBenchFactory(part, small_rig(640, 480))
    service = BenchService(data, factory, processor=factory.processor(child_process))
    try:
        serve(service, data, host=host, port=port, config={"reset_password": True})
    except KeyboardInterrupt:
        pass
    finally:
        service.close()
        factory.close()
    return 0


def run(args):
    if args.serve_only:
        return serve_appliance(Path(args.out), args.part, args.port, args.host)
    from .. import process as proc
    from ..sim import surfaces
    from ..sim.levels import sculpture_levels
    from ..sim.scanrender import render_scan

    surface = surfaces.get(args.sample)
    if not args.step > 0:
        raise SettingError("--step", f"must be a positive number of mm, got {args.step}")
    out = Path(args.out)
    scan_dir, result_dir = out / "scan", out / "result"
    if scan_dir.exists():
        shutil.rmtree(scan_dir)
    levels = sculpture_levels(surface, args.step)
    print(f"Virtual bench: {surface.description}")
    print(
        f"Rendering {len(levels)} frames (2048 x 1536, level step {args.step:g} mm, "
        f"effects '{args.effects}') into {scan_dir} ...",
        flush=True,
    )
    t0 = time.perf_counter()
    render_scan(surface, scan_dir, levels=levels, effects=args.effects, seed=1, workers=2)
    t1 = time.perf_counter()
    print(
        f"  rendered in {t1 - t0:.1f} s. Processing with ours and with the seed method ...",
        flush=True,
    )
    job = proc.process(scan_dir, compare=True, truth=surface)
    written = proc.write_outputs(job, result_dir)
    t2 = time.perf_counter()
    print(f"  processed in {t2 - t1:.1f} s.")
    print_table(job)
    print(f"\nOutputs in {result_dir}/: {', '.join(written)}")
    for name in ("toolpath.gcode", "toolpath-dissertation.gcode"):
        if (result_dir / name).exists():
            print(f"G-code {result_dir / name}: {check_gcode(result_dir / name)}")
    print(f"Report: {result_dir / 'report.md'}")
    if args.serve:
        return serve_appliance(out, args.part, args.port, args.host)
    return 0
