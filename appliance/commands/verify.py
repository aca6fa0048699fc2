"""inkslice verify toolpath.gcode --against heightmap.csv

Exit codes: 0 the program keeps within --max-gouge of the design; 1 it cuts deeper
(the report is printed, and one error line says by how much); 2 bad input.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .. import atomicio, progress
from ..errors import InkSliceError, SettingError
from ..outputs import read_heightmap_csv
from ._flags import flags

# our finishing programs keep within 0.005 mm (tests/test_cam_scallop.py); twice that
# tolerates the simulation's lattice, and a program that digs into the part fails
DEFAULT_MAX_GOUGE = 0.01

NAME = "verify"
ORDER = 31
HELP = "simulate a G-code program on a block and report gouge, scallop and uncut area against a height map"
PROGRESS = True  # cli.py shows the stages


def add_arguments(p):
    p.add_argument("gcode", help="program to check (ours, or any G0/G1 program)")
    p.add_argument("--against", required=True, help="heightmap.csv of the design surface")
    p.add_argument(
        "--cutter", default=None, help="cutter, if the program does not name it (ball6, flat3, bull6r1)"
    )
    p.add_argument(
        "--z-zero",
        default=None,
        help="height above the base top of the program's Z0, mm, or "
        "'top' (the part's top, as the dissertation's programs use); default: from the "
        "program's header, else 0",
    )
    p.add_argument("--resolution", type=float, default=0.1, help="stock lattice spacing, mm (default 0.1)")
    p.add_argument(
        "--scallop", type=float, default=0.05, help="requested scallop (scale of the PNG), mm (default 0.05)"
    )
    p.add_argument(
        "--edge-band",
        type=float,
        default=0.0,
        help="band inside the part's edge left out of the scallop figures, mm (default 0: "
        "the whole surface the cutter can reach, its rim included)",
    )
    p.add_argument(
        "--reach-tol",
        type=float,
        default=0.005,
        help="a cell counts as reachable when the cutter's opening of the design is within this of it, mm",
    )
    p.add_argument(
        "--uncut-tol", type=float, default=0.1, help="material above the design counted as uncut, mm"
    )
    p.add_argument("--png", default=None, help="deviation map to write (default: GCODE with .png)")
    p.add_argument(
        "--max-gouge",
        type=float,
        default=DEFAULT_MAX_GOUGE,
        help=f"exit 1 if the program cuts deeper than this into the design, mm (default {DEFAULT_MAX_GOUGE})",
    )


def run(args):
    import numpy as np

    from ..cam.jobs import verify_gcode
    from ..cam.millsim import deviation_png
    from ..cam.sampling import check_heightmap

    path = Path(args.gcode)
    if not path.is_file():
        raise InkSliceError(path, "G-code file does not exist")
    if not np.isfinite(args.scallop) or args.scallop <= 0:
        raise SettingError("--scallop", f"must be > 0 mm, got {args.scallop}")
    if not (np.isfinite(args.max_gouge) and args.max_gouge >= 0):
        # NaN compared false with every gouge: the check always passed
        raise SettingError("--max-gouge", f"must be >= 0 mm, got {args.max_gouge}")
    png = Path(args.png) if args.png else path.with_suffix(".png")
    atomicio.check_output_file(png, "--png")  # before the simulation, not after it
    text = path.read_text(encoding="utf-8", errors="replace")
    hm = read_heightmap_csv(args.against)
    check_heightmap(hm, where=args.against)  # its problems named by the file
    z_zero = args.z_zero
    if z_zero is not None:
        if str(z_zero).lower() == "top":
            z_zero = float(np.nanmax(hm.z))
        else:
            try:
                z_zero = float(z_zero)
            except ValueError:
                raise SettingError("--z-zero", f"{args.z_zero!r} is not a number or 'top'") from None
    progress.stage("simulated milling")
    with flags({"cutter": "--cutter", "z zero": "--z-zero"}):
        rep, info = verify_gcode(
            text,
            hm,
            cutter=args.cutter,
            z_zero=z_zero,
            resolution=args.resolution,
            reach_tol=args.reach_tol,
            edge_band=args.edge_band,
            uncut_tol=args.uncut_tol,
            where=str(path),
        )
    print(
        f"{path}: {info['moves']} moves, cutter {info['cutter']}, program Z0 at {info['z_zero']:.3f} mm "
        "above the base top"
    )
    for line in rep.lines():
        print(line)
    atomicio.write_bytes(png, deviation_png(rep, scallop_scale=2 * args.scallop))
    print(f"deviation map: {png}")
    if not rep.gouge <= args.max_gouge:
        print(
            f"inkslice: error: {path}: cuts {rep.gouge:.4f} mm into the design at x={rep.gouge_at[0]:.2f} "
            f"y={rep.gouge_at[1]:.2f} mm, more than --max-gouge {args.max_gouge:g} mm",
            file=sys.stderr,
        )
        return 1
    return 0
