"""inkslice process SCAN -o OUT"""

from ..process import OUR_METHODS, PIPELINES, label, process_scan
from ..surface.seed import METHODS

NAME = "process"
ORDER = 20
HELP = "turn a scan folder into heightmap.csv, surface.stl, G-code and a report"
PROGRESS = True  # cli.py shows the stages (waterlines, surface, toolpath, ...)


def add_arguments(p):
    p.add_argument("scan", help="scan folder (with scan.json and frames/)")
    p.add_argument(
        "-o", "--out", required=True, help="output folder (created; files are replaced atomically)"
    )
    p.add_argument(
        "--pipeline",
        default="inkslice",
        choices=PIPELINES,
        help="inkslice (ours, default) or seed (the seed method: the 2013 dissertation's Canny pipeline)",
    )
    p.add_argument(
        "--method",
        default=None,
        choices=OUR_METHODS + METHODS,
        help="surface method for heightmap.csv and the G-code (default: fit for inkslice, lsq3 for seed)",
    )
    p.add_argument("--grid", type=int, default=50, help="cells per side of the grid (default 50)")
    p.add_argument("--spacing", type=float, default=None, help="grid spacing in mm instead of --grid")
    p.add_argument(
        "--compare",
        action="store_true",
        help="also run the other pipeline's methods on the same frames, for the report",
    )
    p.add_argument(
        "--truth",
        default=None,
        help="ground truth: a .truth.json file or a surface name (default: SCAN.truth.json if present)",
    )
    p.add_argument("--no-displacement", action="store_true", help="do not correct levels for displaced ink")
    p.add_argument(
        "--meniscus",
        default=None,
        help="meniscus model JSON from `inkslice calibrate --reference` (default: scan.json's, if any)",
    )
    p.add_argument("--cutter", default="ball6", help="finishing cutter (default ball6)")
    p.add_argument("--scallop", type=float, default=0.05, help="finishing scallop height, mm (default 0.05)")
    p.add_argument("--dialect", default="linuxcnc", help="G-code dialect (default linuxcnc)")


def run(args):
    from ..sim.truth import find_truth

    truth = find_truth(args.scan, args.truth)
    result = process_scan(
        args.scan,
        args.out,
        pipeline=args.pipeline,
        method=args.method,
        grid_n=args.grid,
        spacing_mm=args.spacing,
        truth=truth,
        compare=args.compare,
        displacement=not args.no_displacement,
        meniscus=args.meniscus,
        cam_options={"cutter": args.cutter, "scallop": args.scallop, "dialect": args.dialect},
    )
    for name in result["outputs"]:
        print(f"{args.out}/{name}")
    for note in result["notes"]:
        print(f"note: {note}")
    if result["statistics"]:
        for key, s in result["statistics"].items():
            print(
                f"{label(key)}: Ea {s['Ea']:.4f} mm, sigma {s['sigma']:.4f} mm, "
                f"max {s['max_error']:.4f} mm, matching {s['matching']:.4f} %"
            )
    return 0
