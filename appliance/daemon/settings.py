"""The daemon's settings: defaults, and validation that names the bad key.

Bench settings (calibration, timing) and per-scan defaults share one flat
namespace; a scan's parameters may override any per-scan key, and the job
keeps its own copy so a resumed scan uses the settings it started with.
"""
from __future__ import annotations

import math

from ..errors import SettingError

DEFAULTS = {
    # the scan: levels from the top (part submerged) down to the bottom (fully exposed)
    "levels_to_mm": 20.0,          # first level (top)
    "levels_from_mm": 0.0,         # last level (bottom: the base top)
    "step_mode": "fixed",          # fixed | adaptive
    "level_step_mm": 0.5,          # fixed step; the adaptive step's starting value
    "step_min_mm": 0.1,            # adaptive bounds
    "step_max_mm": 2.0,
    "adaptive_change": 0.02,       # adaptive target: fraction of the part's pixels changing per step
    "settle_s": 0.5,               # wait after each move for ripples to die out
    # the bench (found by calibration)
    "level_at_home_mm": 60.0,      # liquid level above the base top with the stage at home
    "min_free_mb": 200.0,          # stop a scan before the disk is this full
    "preview_width": 480,          # latest_frame() JPEG width
    "auto_resume": False,          # resume an interrupted scan when the daemon starts
    # processing (passed to process_scan; "" = its own default)
    "pipeline": "",                # "" = processing's default; e.g. "seed" = the dissertation's (fast)
    "method": "",
    "grid": 50,
    "scallop_mm": 0.05,            # finishing: scallop height the stepover is chosen for
    # the machine and cutter (kept with the job; used by the toolpath stage)
    "cutter_type": "ball",
    "cutter_diameter_mm": 6.0,
    "stepover_mm": 1.0,
    "feed_mm_min": 800.0,
    "dialect": "linuxcnc",
    "envelope_x_mm": 200.0,
    "envelope_y_mm": 150.0,
    "envelope_z_mm": 60.0,
}
CHOICES = {"step_mode": ("fixed", "adaptive"), "cutter_type": ("ball", "flat"),
           "dialect": ("linuxcnc", "grbl", "fanuc")}
# What each setting means, for the operator: docs/settings.md is generated from these
# definitions (scripts/gen_settings_doc.py), so a new setting needs its sentence here.
HELP = {
    "levels_to_mm": "The first (highest) level of a scan, in mm above the base top. Set it a little above "
                    "the part's top; when the first frame already shows the part the scan starts higher "
                    "by itself.",
    "levels_from_mm": "The last (lowest) level: 0 is the base top, where the part is fully out of the ink.",
    "step_mode": "`fixed` steps by `level_step_mm`; `adaptive` goes finer where the waterline changes fast "
                 "and coarser where it hardly moves.",
    "level_step_mm": "The step between levels (fixed mode), and the first step of an adaptive scan. Smaller "
                     "steps follow steep and detailed parts better and take longer.",
    "step_min_mm": "The smallest step an adaptive scan takes.",
    "step_max_mm": "The largest step an adaptive scan takes.",
    "adaptive_change": "What an adaptive scan aims at: the fraction of the part's outline that moves from "
                       "one frame to the next.",
    "settle_s": "Seconds to wait after each move before the frame is taken, for ripples on the ink to die out.",
    "level_at_home_mm": "The ink's level above the base top with the stage at home. Commissioning measures "
                        "it (level zero); every level of a scan is counted from it.",
    "min_free_mb": "A scan stops (keeping its frames) before the data disk has less than this free.",
    "preview_width": "Width in pixels of the live camera picture on the dashboard.",
    "auto_resume": "Resume a scan that a power cut or crash interrupted as soon as the daemon starts again.",
    "pipeline": "Which processing a finished scan gets: empty for ours, `seed` for the dissertation's "
                "(faster, much less accurate).",
    "method": "The surface method: empty for the pipeline's own (`fit` for ours, `lsq3` for the "
              "dissertation's), or another one to compare (the dissertation's methods run on our waterlines).",
    "grid": "Cells a side of the height map written to heightmap.csv.",
    "scallop_mm": "The ridge height the finishing program leaves between two passes; the stepover is "
                  "chosen for it. Smaller is smoother and slower to compute and to mill.",
    "cutter_type": "The finishing cutter's end: `ball` or `flat`.",
    "cutter_diameter_mm": "The finishing cutter's diameter.",
    "stepover_mm": "Accepted and checked, not used yet: the stepover follows from `scallop_mm`.",
    "feed_mm_min": "Accepted and checked, not used yet: feeds come from the cutter and the material.",
    "dialect": "The controller the G-code is written for: `linuxcnc`, `grbl` or `fanuc`.",
    "envelope_x_mm": "Accepted and checked, not used yet (the machine's X travel).",
    "envelope_y_mm": "Accepted and checked, not used yet (the machine's Y travel).",
    "envelope_z_mm": "The machine's Z travel; the top level of a scan may not exceed it.",
}


def surface_methods() -> tuple:
    """The surface methods processing knows ("" = its default), asked of the pure room."""
    try:
        from ..surface.reconstruct import METHODS
    except ImportError:
        from ..surface.seed import METHODS
    return ("",) + tuple(METHODS)
BOOLS = {"auto_resume"}
INTS = {"grid": (3, 2000), "preview_width": (64, 2048)}
# (lowest, highest, whether the lowest itself is allowed): what a bench box can do.
# A setting outside is a typo or an attack, and a disk-space floor of 0 is no floor.
RANGES = {
    "levels_to_mm": (0.0, 1000.0, False), "levels_from_mm": (0.0, 1000.0, True),
    "level_step_mm": (0.0, 100.0, False), "step_min_mm": (0.0, 100.0, False), "step_max_mm": (0.0, 100.0, False),
    "adaptive_change": (0.0, 1.0, False), "settle_s": (0.0, 600.0, True),
    "level_at_home_mm": (0.0, 1000.0, False), "min_free_mb": (50.0, 1e6, True),
    "scallop_mm": (0.0, 5.0, False), "cutter_diameter_mm": (0.1, 100.0, True), "stepover_mm": (0.0, 100.0, False),
    "feed_mm_min": (1.0, 100000.0, True),
    "envelope_x_mm": (1.0, 10000.0, True), "envelope_y_mm": (1.0, 10000.0, True), "envelope_z_mm": (1.0, 10000.0, True),
}
MAX_LEVELS = 5000


def pipelines() -> tuple:
    from ..process import PIPELINES
    return ("",) + tuple(PIPELINES)


def _check_value(key, value):
    if key == "pipeline":
        if value not in pipelines():
            raise SettingError(key, f"must be one of {', '.join(p for p in pipelines() if p)} "
                                    f"(or empty for the default), got {value!r}")
        return value
    if key == "method":
        if value not in surface_methods():
            raise SettingError(key, f"must be one of {', '.join(m for m in surface_methods() if m)} "
                                    f"(or empty for the default), got {value!r}")
        return value
    if key in CHOICES:
        if value not in CHOICES[key]:
            raise SettingError(key, f"must be one of {', '.join(CHOICES[key])}, got {value!r}")
        return value
    if key in BOOLS:
        if not isinstance(value, bool):
            raise SettingError(key, f"must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SettingError(key, f"must be a number, got {value!r}")
    if key in INTS:
        lo, hi = INTS[key]
        if int(value) != value or not lo <= value <= hi:
            raise SettingError(key, f"must be a whole number in {lo}..{hi}, got {value!r}")
        return int(value)
    lo, hi, lo_ok = RANGES[key]
    if not ((value >= lo if lo_ok else value > lo) and value <= hi):
        if lo == 0 and not lo_ok and value <= 0:
            raise SettingError(key, f"must be positive, got {value!r}")
        raise SettingError(key, f"must be {'at least' if lo_ok else 'more than'} {lo:g} and at most {hi:g}, "
                                f"got {value!r}")
    return float(value)


def validate(current: dict, changes: dict) -> dict:
    """current + changes, checked key by key and as a whole."""
    if not isinstance(changes, dict):
        raise SettingError("settings", "changes must be an object of key: value")
    new = dict(current)
    for key, value in changes.items():
        if key not in DEFAULTS:
            raise SettingError(key, "unknown setting")
        new[key] = _check_value(key, value)
    if new["levels_to_mm"] <= new["levels_from_mm"]:
        raise SettingError("levels_to_mm", f"the top level {new['levels_to_mm']} must be above the bottom "
                                           f"level {new['levels_from_mm']}")
    if new["levels_to_mm"] > new["level_at_home_mm"]:
        raise SettingError("levels_to_mm", f"{new['levels_to_mm']} mm is above the level with the stage at "
                                           f"home ({new['level_at_home_mm']} mm): the stage cannot go below home")
    if new["levels_to_mm"] > new["envelope_z_mm"]:
        raise SettingError("levels_to_mm", "above the machine envelope's Z travel")
    if new["step_min_mm"] > new["step_max_mm"]:
        raise SettingError("step_min_mm", "must not exceed step_max_mm")
    smallest = new["level_step_mm"] if new["step_mode"] == "fixed" else new["step_min_mm"]
    n = (new["levels_to_mm"] - new["levels_from_mm"]) / smallest
    if new["step_mode"] == "fixed" and n + 1 > MAX_LEVELS:
        raise SettingError("level_step_mm", f"{int(n) + 1} levels is more than a scan may take ({MAX_LEVELS})")
    return new


def full(settings: dict) -> dict:
    """Stored settings over the defaults (a newer version may add keys)."""
    return {**DEFAULTS, **{k: v for k, v in settings.items() if k in DEFAULTS}}
