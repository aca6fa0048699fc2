"""inkslice process SCAN -o OUT"""
from ..process import process_scan
from ..surface.seed import METHODS

NAME = "process"
ORDER = 20
HELP = "turn a scan folder into heightmap.csv, G-code and a report"


def add_arguments(p):
    p.add_argument("scan", help="scan folder (with scan.json and frames/)")
    p.add_argument("-o", "--out", required=True, help="output folder (created; files are replaced atomically)")
    p.add_argument("--method", default="lsq3", choices=METHODS,
                   help="surface method written to heightmap.csv and the G-code (default lsq3)")
    p.add_argument("--grid", type=int, default=50, help="cells per side of the grid (default 50)")
    p.add_argument("--truth", default=None,
                   help="ground truth: a .truth.json file or a surface name (default: SCAN.truth.json if present)")


def run(args):
    result = process_scan(args.scan, args.out, method=args.method, grid_n=args.grid, truth=args.truth)
    for name in result["outputs"]:
        print(f"{args.out}/{name}")
    if result["statistics"]:
        s = result["statistics"][result["method"]]
        print(f"{result['method']}: Ea {s['Ea']:.4f} mm, sigma {s['sigma']:.4f} mm, "
              f"max {s['max_error']:.4f} mm, matching {s['matching']:.4f} %")
    return 0
