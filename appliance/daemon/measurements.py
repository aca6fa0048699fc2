"""The measurements behind the commissioning steps, apart from the wizard that asks for them.

Why apart: each is a small piece of bench science (search for where the base top meets the
ink, a camera model from board views, a tank's area, the reference scan's levels and its
processing) that can be read and tested on its own; commissioning.py only asks the person for
what must be on the base, runs these and keeps the results (commissioned.py).

    find_level_zero(shows, guess)        the stage position at which the base top meets the ink
    lens_from_views(views, stored)       the lens: from >= MIN_VIEWS tilted board views, or the stored one
    plane_camera(frame, lens, views)     the liquid plane from the flat board: (camera block, report)
    tank_result(values)                  the tank's inner area, entered as area or width x depth
    reference_scan_changes(d, step)      the levels a scan of a d mm reference ball needs
    reference_processor(reference)       the processing of that scan: the meniscus fit, the ball's error
"""

from __future__ import annotations

import math
from collections.abc import Callable

import cv2
import numpy as np

from ..errors import Cancelled, SettingError
from ..vision.calibration import camera_json, find_corners, intrinsics, plane_homography
from ..vision.printboard import describe as print_instructions
from ..vision.printboard import printed_size_mm
from .calibration import BOARD, JIG

MIN_VIEWS = 3
LEVEL_SEARCH_MM = 12.0  # level zero is searched this far either side of the current setting
LEVEL_RESOLUTION_MM = 0.01
BASE_SHOWS = 0.25  # fraction of the frame the base top covers once it stands above the ink
BALL_MM = 25.4
TANK_MM2 = (100.0, 1e6)  # what can be a tank's inner area


def bright_fraction(frame) -> float:
    """Share of the frame brighter than the ink (the lit base top or part)."""
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    small = cv2.resize(
        gray, (256, max(1, round(gray.shape[0] * 256 / gray.shape[1]))), interpolation=cv2.INTER_AREA
    )
    return float(np.mean(small > 90))


def base_shows(frame) -> bool:
    return bright_fraction(frame) > BASE_SHOWS


def positive_mm(values: dict, key: str) -> float:
    v = values.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise SettingError(key, f"must be a positive number of mm, got {v!r}")
    return float(v)


# -- level zero ---------------------------------------------------------------------------------
def find_level_zero(shows: Callable, guess: float) -> tuple[float, np.ndarray]:
    """Raise the base in 1 mm steps from LEVEL_SEARCH_MM below `guess` until its top shows above
    the ink, then halve the bracket to LEVEL_RESOLUTION_MM. `shows(pos)` moves the stage there
    and returns (the base shows, the frame). Returns (stage position, the last frame)."""
    lo = max(guess - LEVEL_SEARCH_MM, 0.0)
    if shows(lo)[0]:
        raise SettingError(
            "level zero",
            f"the base already shows at stage position {lo:.1f} mm; is the tank filled, and the base empty?",
        )
    pos, found = lo, None
    while pos < guess + LEVEL_SEARCH_MM:
        pos = round(pos + 1.0, 6)
        up, frame = shows(pos)
        if up:
            found = pos
            break
    if found is None:
        raise SettingError(
            "level zero",
            f"the base never showed between stage positions {lo:.1f} and "
            f"{pos:.1f} mm: is the light on and the base in view?",
        )
    below, above = found - 1.0, found
    while above - below > LEVEL_RESOLUTION_MM:
        mid = (above + below) / 2
        up, frame = shows(mid)
        if up:
            above = mid
        else:
            below = mid
    return round((above + below) / 2, 4), frame


def level_zero_changes(settings: dict, level_at_home_mm: float) -> dict:
    """The settings a new level zero changes: itself, and a scan range that would start above it."""
    changes = {"level_at_home_mm": level_at_home_mm}
    if settings["levels_to_mm"] > level_at_home_mm:
        changes["levels_to_mm"] = math.floor(level_at_home_mm)
    return changes


# -- camera: lens and liquid plane ---------------------------------------------------------------
def lens_from_views(views: list, stored: dict | None) -> dict:
    """{"K", "dist", "from", ...} from the tilted views, else the stored camera's lens, else {}."""
    if len(views) >= MIN_VIEWS:
        intr = intrinsics(views, BOARD)
        return {"K": intr.K, "dist": intr.dist, "rms_px": intr.rms_px, "from": f"{len(views)} views"}
    if views:
        raise SettingError(
            "views",
            f"{len(views)} board views taken: take at least {MIN_VIEWS} for "
            "the lens, or cancel and start again to keep the stored lens",
        )
    cam = stored or {}
    if cam.get("K") is None:
        return {}
    return {
        "K": np.asarray(cam["K"], float),
        "dist": np.asarray(cam["dist"], float),
        "from": "the stored calibration",
        "height_mm": cam.get("height_mm"),
    }


def plane_camera(frame: np.ndarray, lens: dict, views: int) -> tuple[dict, dict]:
    """The camera block (scan.json's) from the board lying flat at level zero, and a report."""
    K, dist = lens.get("K"), lens.get("dist")
    Hm, height, rms_mm = plane_homography(frame, BOARD, JIG, K, dist, "flat board")
    h, w = frame.shape[:2]
    camera = camera_json((w, h), Hm, K, dist, height if height is not None else lens.get("height_mm"))
    c = np.array([[w / 2, h / 2, 1], [w / 2 + 1, h / 2, 1]]) @ Hm.T
    c = c[:, :2] / c[:, 2:]
    report = {
        "views": views,
        "plane_rms_mm": round(rms_mm, 4),
        "mm_per_px": round(float(np.linalg.norm(c[1] - c[0])), 4),
        "lens": lens.get("from", "none (no lens model)"),
        "camera_height_mm": round(camera["height_mm"], 2) if camera.get("height_mm") else None,
    }
    if "rms_px" in lens:
        report["lens_rms_px"] = round(lens["rms_px"], 4)
    return camera, report


def board_to_print() -> dict:
    """What the page says of the board: its corners and squares, where it lies on the base, how
    many views the lens needs, and the files to print (the web serves them from its static folder)."""
    return {
        "inner_corners": [BOARD.cols, BOARD.rows],
        "square_mm": BOARD.square_mm,
        "jig_first_corner_mm": [JIG.x0, JIG.y0],
        "min_views": MIN_VIEWS,
        "printed_mm": list(printed_size_mm(BOARD)),
        "print": print_instructions(BOARD),
        "files": ["chessboard.pdf", "chessboard.png"],
    }


def board_corners(frame: np.ndarray):
    return find_corners(frame, BOARD)


# -- tank -----------------------------------------------------------------------------------------
def tank_result(values: dict) -> dict:
    if "area_mm2" in values:
        area = positive_mm(values, "area_mm2")
        result = {"area_mm2": round(area, 1), "figure": f"{area:.0f} mm²"}
    else:
        w, d = positive_mm(values, "width_mm"), positive_mm(values, "depth_mm")
        area = w * d
        result = {
            "area_mm2": round(area, 1),
            "width_mm": w,
            "depth_mm": d,
            "figure": f"{w:g} x {d:g} mm = {area:.0f} mm²",
        }
    if not TANK_MM2[0] <= area <= TANK_MM2[1]:
        raise SettingError("tank", f"{area:.0f} mm² is not a tank's inner area (100 .. 1 000 000 mm²)")
    # the ink falls under the camera as the part comes out, unless an overflow or a reservoir
    # holds its surface where the camera was calibrated on it (processing needs to know which)
    held = values.get("level_held", False)
    if not isinstance(held, bool):
        raise SettingError("level_held", f"must be true or false, got {held!r}")
    result["surface_falls"] = not held
    if held:
        result["figure"] += ", the ink's level held by an overflow"
    return result


# -- meniscus: a scan of a reference ball --------------------------------------------------------
def reference_scan_changes(diameter_mm: float, step_mm: float) -> dict:
    """Fixed steps from just below the ball's equator to 1 mm above its top."""
    return {
        "levels_to_mm": math.ceil((diameter_mm + 1.0) / step_mm) * step_mm,
        "levels_from_mm": max(round(diameter_mm / 2 - 2.0, 3), 0.0),
        "level_step_mm": step_mm,
        "step_mode": "fixed",
    }


def reference_processor(reference: dict):
    """The processor of a reference scan (the meniscus step): fit the meniscus, process the scan
    with it and measure the ball; writes reference.json, meniscus.json and heightmap.csv."""

    def run(scan_folder, out_folder, options, stop=None):
        from pathlib import Path

        from .. import atomicio
        from ..outputs import meniscus_json, write_heightmap_csv
        from ..process import extract_waterlines, process
        from ..scanfile import load_scan
        from ..surface.reference import Ball, fit_meniscus, reference_error

        def check_stop():  # it runs in the scan's thread: a cancel must not wait for it
            if stop is not None and stop.is_set():
                raise Cancelled()

        scan = load_scan(scan_folder)
        waterlines = extract_waterlines(scan)
        check_stop()
        model, ball = fit_meniscus(scan, Ball(float(reference["diameter_mm"])), waterlines)
        check_stop()
        job = process(
            scan_folder,
            truth=False,
            meniscus=model,
            **{k: v for k, v in options.items() if k in ("grid_n", "method")},
        )
        hm = job.heightmap
        err = reference_error(ball, hm)
        out = Path(out_folder)
        result = {
            "capillary_length_mm": round(model.capillary_length_mm, 4),
            "contact_angle_deg": round(math.degrees(model.contact_angle_rad), 3),
            "contact_line_curvature": round(model.curvature, 3),
            "reference": {**ball.to_json(), **err},
            "reference_job": scan.extra.get("job"),
            "tank_area_mm2": scan.tank_area_mm2,
        }
        atomicio.write_json(out / "reference.json", result)
        atomicio.write_json(out / "meniscus.json", meniscus_json(model))
        write_heightmap_csv(out / "heightmap.csv", hm)
        # a measurement, not a part to mill: the job is done without a finishing program
        return {"outputs": ["heightmap.csv", "meniscus.json", "reference.json"], "makes_program": False}

    return run
