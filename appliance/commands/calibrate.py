"""inkslice calibrate: the camera, or the meniscus.

Camera: reads chessboard images (several views for the lens, one board lying
on the liquid plane for the homography), runs appliance.vision.calibration and
writes the result atomically as exactly scan.json's "camera" block.

Meniscus (--reference ball|sphere|cone --scan SCAN): a scan of a reference part
of known shape; the contact line's offset from the level on its slopes gives the
ink's capillary length and contact angle (surface/reference.py fit_meniscus),
written as meniscus.json for `inkslice process --meniscus`. A ball (--diameter,
default 25.4 mm) is found wherever it lies on the base; sphere and cone are the
virtual bench's reference parts at their known places. The daemon's
commissioning does the same from its own reference scan and writes the model
into every scan.json.

The previous file is kept as *.prev.json; on any error nothing is written.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2

from .. import atomicio
from ..datadir import data_dir
from ..errors import SettingError
from ..vision.calibration import Board, BoardPose, CalibrationError, calibrate

NAME = "calibrate"
ORDER = 30
HELP = "calibrate the camera from chessboard images, or the meniscus from a reference scan"


def default_out(reference=False) -> Path:
    return data_dir() / ("meniscus.json" if reference else "calibration.json")


def add_arguments(p):
    p.add_argument("images", nargs="*", help="chessboard images at different angles (3 or more) for the lens")
    p.add_argument("--plane", help="image of the board lying on the liquid plane")
    p.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    p.add_argument("--square-mm", type=float, help="side of a board square, mm")
    p.add_argument(
        "--board-origin",
        nargs=2,
        type=float,
        default=(0.0, 0.0),
        metavar=("X", "Y"),
        help="object-frame mm of the inner corner seen nearest the image's top-left",
    )
    p.add_argument(
        "--board-angle",
        type=float,
        default=0.0,
        help="direction of the board's rows in the object frame, degrees from +x (default 0)",
    )
    p.add_argument("--out", default=None, help=f"where to write the camera block (default {default_out()})")
    p.add_argument(
        "--reference",
        choices=("ball", "sphere", "cone"),
        default=None,
        help="meniscus calibration from a scan of this reference part (give --scan)",
    )
    p.add_argument("--diameter", type=float, default=25.4, help="with --reference ball: its diameter, mm")
    p.add_argument("--scan", default=None, help="with --reference: the reference part's scan folder")


def _board(args):
    try:
        cols, rows = (int(v) for v in args.pattern.lower().split("x"))
    except ValueError:
        raise SettingError("--pattern", f"expected COLSxROWS like 9x6, got {args.pattern!r}") from None
    if cols < 3 or rows < 3:
        raise SettingError("--pattern", "a board needs at least 3x3 inner corners")
    if not args.square_mm > 0:
        raise SettingError("--square-mm", f"must be positive, got {args.square_mm}")
    return Board(cols, rows, args.square_mm)


def _read(path):
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(p, "image file is missing")
    img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise CalibrationError(p, "does not load as an image")
    return img


def run(args):
    if args.reference is not None:
        return run_reference(args)
    if len(args.images) < 3 or not args.plane or not args.square_mm:
        raise SettingError(
            "calibrate", "the camera needs 3 or more board images, --plane IMAGE and --square-mm"
        )
    board = _board(args)
    pose = BoardPose(args.board_origin[0], args.board_origin[1], args.board_angle)
    boards = [_read(p) for p in args.images]
    plane = _read(args.plane)
    camera, report = calibrate(boards, plane, board, pose, board_names=args.images, plane_name=args.plane)
    out = Path(args.out) if args.out else default_out()
    if out.is_file():
        atomicio.write_bytes(out.with_name(out.stem + ".prev" + out.suffix), out.read_bytes())
    atomicio.write_text(out, json.dumps(camera, indent=2) + "\n")
    print(f"calibration written to {out}")
    print(
        f"  lens: {report['images']} images, corner reprojection RMS {report['reprojection_rms_px']:.3f} px"
    )
    print(
        f"  liquid plane: corner RMS {report['plane_rms_mm'] * 1000:.1f} um"
        + (f", camera {camera['height_mm']:.1f} mm above the liquid" if "height_mm" in camera else "")
    )
    return 0


def run_reference(args):
    from ..outputs import meniscus_json
    from ..process import extract_waterlines
    from ..scanfile import load_scan
    from ..surface.reference import Ball, fit_meniscus

    if not args.scan:
        raise SettingError("--scan", "--reference needs the reference part's scan folder")
    if args.reference == "ball":
        if not 1.0 <= args.diameter <= 100.0:
            raise SettingError("--diameter", f"a reference ball of {args.diameter} mm: use 1 to 100 mm")
        part = Ball(args.diameter)
    else:
        from ..sim import surfaces  # the virtual bench's own reference parts

        part = surfaces.get(args.reference)
    scan = load_scan(args.scan)
    model, part = fit_meniscus(scan, part, extract_waterlines(scan))
    out = Path(args.out) if args.out else default_out(reference=True)
    if out.is_file():
        atomicio.write_bytes(out.with_name(out.stem + ".prev" + out.suffix), out.read_bytes())
    atomicio.write_text(out, json.dumps(meniscus_json(model), indent=2) + "\n")
    print(
        f"meniscus written to {out}: capillary length {model.capillary_length_mm:.3f} mm, "
        f"contact angle {math.degrees(model.contact_angle_rad):.2f} deg, "
        f"contact line curvature weight {model.curvature:.2f}"
    )
    return 0
