"""`inkslice render`: a simulated scan of a known part (the virtual bench)."""

from __future__ import annotations

import os

NAME = "render"
HELP = "render a simulated scan folder of a known part (virtual bench)"
ORDER = 60


def add_arguments(p):
    from ..sim.effects import PRESETS
    from ..sim.surfaces import SURFACES

    p.add_argument("surface", choices=sorted(SURFACES), help="known part to scan")
    p.add_argument("-o", "--output", required=True, metavar="SCAN", help="scan folder to write")
    p.add_argument("--step", type=float, default=1.0, metavar="MM", help="level step (default 1.0)")
    p.add_argument(
        "--effects", default="clean", choices=sorted(PRESETS), help="image effects preset (default clean)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--workers", type=int, default=1, metavar="N", help="render frames in N processes (default 1)"
    )
    p.add_argument(
        "--refine-mm",
        type=float,
        default=0.0,
        metavar="MM",
        help="bisect the steps in which a face came out at once to MM, as the daemon's "
        "runner does (default 0: only the steps)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress output")


def run(args) -> int:
    from .. import progress
    from ..sim.scanrender import render_scan, truth_path

    def frames(i, n):
        if i <= 1:
            progress.stage("frames", total=n)
        progress.step(i, n)

    with progress.shown(open(os.devnull, "w") if args.quiet else None) as shown:
        scan = render_scan(
            args.surface,
            args.output,
            step_mm=args.step,
            effects=args.effects,
            seed=args.seed,
            progress=frames,
            workers=args.workers,
            refine_mm=args.refine_mm,
        )
    if args.quiet:
        shown.stream.close()
    print(f"{len(scan.frames)} frames of {args.surface} in {scan.folder} (truth: {truth_path(scan.folder)})")
    return 0
