"""inkslice calibrate: camera intrinsics, distortion and the liquid-plane homography.

Reads chessboard images (several views for the lens, one board lying on the
liquid plane for the homography), runs appliance.vision.calibration and writes
the result atomically as exactly scan.json's "camera" block. The previous
calibration is kept as calibration.prev.json; on any error nothing is written.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import cv2

from .. import atomicio
from ..errors import SettingError
from ..vision.calibration import Board, BoardPose, CalibrationError, calibrate

NAME = "calibrate"
ORDER = 30
HELP = "calibrate the camera from chessboard images (lens + liquid-plane homography)"


def data_dir() -> Path:
    env = os.environ.get("INKSLICE_DATA")
    return Path(env) if env else Path.home() / ".local" / "share" / "inkslice"


def default_out() -> Path:
    return data_dir() / "calibration.json"


def add_arguments(p):
    p.add_argument("images", nargs="+", help="chessboard images at different angles (3 or more) for the lens")
    p.add_argument("--plane", required=True, help="image of the board lying on the liquid plane")
    p.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    p.add_argument("--square-mm", type=float, required=True, help="side of a board square, mm")
    p.add_argument("--board-origin", nargs=2, type=float, default=(0.0, 0.0), metavar=("X", "Y"),
                   help="object-frame mm of the inner corner seen nearest the image's top-left")
    p.add_argument("--board-angle", type=float, default=0.0,
                   help="direction of the board's rows in the object frame, degrees from +x (default 0)")
    p.add_argument("--out", default=None, help=f"where to write the camera block (default {default_out()})")
    p.add_argument("--reference", choices=("sphere", "cone"), default=None,
                   help="meniscus calibration from a scan of a reference part (not available yet)")


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
        # the surface team's meniscus calibration plugs in here (wired by the lead)
        raise SettingError("--reference", "meniscus calibration from a reference part is not available yet")
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
    print(f"  lens: {report['images']} images, corner reprojection RMS {report['reprojection_rms_px']:.3f} px")
    print(f"  liquid plane: corner RMS {report['plane_rms_mm'] * 1000:.1f} um"
          + (f", camera {camera['height_mm']:.1f} mm above the liquid" if "height_mm" in camera else ""))
    return 0
