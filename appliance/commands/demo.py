"""inkslice demo: a scan of a dissertation sample on the virtual bench, processed end to end."""
from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

from ..errors import SettingError

NAME = "demo"
ORDER = 10
HELP = "render a scan of a sample on the virtual bench, process it, print the statistics table"


def add_arguments(p):
    p.add_argument("--sample", default="sample3", help="known part to scan (default sample3)")
    p.add_argument("--step", type=float, default=1.0, help="level step in mm (default 1)")
    p.add_argument("--effects", default="realistic", help="virtual bench effects preset (default realistic)")
    p.add_argument("--out", default="demo-out", help="output folder (default ./demo-out)")


def print_table(job, out=sys.stdout):
    from ..surface.seed import LABELS
    from ..surface.seedtables import TABLES
    key = {"captured": "captured", "spline": "spline", "nearest": "nearest", "lsq3": "lsq"}
    ref_of = TABLES.get(job.truth, {})
    print(f"\n{'method':<26} {'max mm':>8} {'Ea mm':>8} {'sigma':>8} {'Ep %':>8} {'match %':>9}"
          f"  | dissertation Ea / sigma / Ep", file=out)
    for m, s in job.stats.items():
        ref = ref_of.get(key.get(m, ""))
        tail = f"  | {ref[0]:.4f} / {ref[1]:.4g} / {ref[2]:.4f}" if ref else ""
        print(f"{LABELS[m]:<26} {s['max_error']:8.4f} {s['Ea']:8.4f} {s['sigma']:8.4f} "
              f"{s['Ep_table']:8.4f} {s['matching']:9.4f}{tail}", file=out)


def check_gcode(path):
    rs274 = shutil.which("rs274")
    if not rs274:
        return "not checked (LinuxCNC's rs274 is not installed)"
    with open(Path(path).parent / "rs274.txt", "w") as log:
        rc = subprocess.run([rs274, "-g", str(path), str(Path(path).parent / "rs274.txt")],
                            stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT).returncode
    return "accepted by LinuxCNC's rs274 -g" if rc == 0 else f"REJECTED by rs274 (exit {rc})"


def run(args):
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
    print(f"Rendering {len(levels)} frames (2048 x 1536, level step {args.step:g} mm, "
          f"effects '{args.effects}') into {scan_dir} ...", flush=True)
    t0 = time.perf_counter()
    render_scan(surface, scan_dir, levels=levels, effects=args.effects, seed=1)
    t1 = time.perf_counter()
    print(f"  rendered in {t1 - t0:.1f} s. Processing with the dissertation's pipeline ...", flush=True)
    job = proc.process(scan_dir, method="lsq3")
    written = proc.write_outputs(job, result_dir)
    t2 = time.perf_counter()
    print(f"  processed in {t2 - t1:.1f} s.")
    print_table(job)
    print(f"\nOutputs in {result_dir}/: {', '.join(written)}")
    print(f"G-code {result_dir / 'toolpath.gcode'}: {check_gcode(result_dir / 'toolpath.gcode')}")
    print(f"Report: {result_dir / 'report.md'}")
    return 0
