"""The daemon's settings: one schema that the daemon, the web form, the CLI and the docs all read.

Each setting is a `Setting`: its type, unit, range or choices, a plain label, the sentence that
explains it and the group it sits in on the web form. validate() checks changes against it, the web
form is drawn from schema_json(), `inkslice settings` parses and checks with the same code, and
docs/settings.md is generated from it (scripts/gen_settings_doc.py). A new setting is one entry in
SCHEMA; nothing else needs to learn about it.

Bench settings (calibration, timing) and per-scan defaults share one flat
namespace; a scan's parameters may override any per-scan key, and the job
keeps its own copy so a resumed scan uses the settings it started with.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

from ..errors import SettingError

# The web form's sections, in order: (id, title).
GROUPS = (
    ("scanning", "Scanning"),
    ("stage", "Stage"),
    ("camera", "Camera"),
    ("cam", "CAM (the milling program)"),
    ("network", "Network and notifications"),
    ("security", "Security"),
)
KINDS = ("number", "int", "bool", "choice", "text")


@dataclass(frozen=True)
class Setting:
    key: str
    default: object
    kind: str  # one of KINDS
    group: str  # one of GROUPS' ids
    label: str  # the form's plain name
    help: str  # what it does, for the operator (the form's explanation, the docs)
    unit: str = ""  # mm, s, mm/min, px ...; every number has one
    lo: float | None = None  # number/int: the range
    hi: float | None = None
    lo_ok: bool = True  # whether lo itself is allowed
    choices: tuple | Callable | None = None  # choice: the values, or a function giving them
    pattern: str | None = None  # text: what a value must match (the empty string always may)
    pattern_says: str = ""  # text: the rule in words, for the refusal
    secret: bool = False  # left out of support bundles
    step: float | None = None  # the form's increment

    def allowed(self) -> tuple:
        c = self.choices() if callable(self.choices) else self.choices
        return tuple(c) if c is not None else (True, False) if self.kind == "bool" else ()


def surface_methods() -> tuple:
    """The surface methods processing knows ("" = its default), asked of the pure room."""
    try:
        from ..surface.reconstruct import METHODS
    except ImportError:
        from ..surface.seed import METHODS
    return ("",) + tuple(METHODS)


def pipelines() -> tuple:
    from ..process import PIPELINES

    return ("",) + tuple(PIPELINES)


def dialects() -> tuple:
    """Every controller `inkslice toolpath --dialect` writes for: the web offers the same ones."""
    from ..cam.posts import DIALECT_NAMES

    return tuple(DIALECT_NAMES)


URL = r"https?://[^\s]{1,500}"
SCHEMA = (
    # -- scanning: levels from the top (part submerged) down to the bottom (fully exposed)
    Setting(
        "levels_to_mm",
        20.0,
        "number",
        "scanning",
        "Top level",
        unit="mm",
        lo=0.0,
        hi=1000.0,
        lo_ok=False,
        step=0.5,
        help="The first (highest) level of a scan, in mm above the base top. Set it a little above "
        "the part's top; when the first frame already shows the part the scan starts higher "
        "by itself.",
    ),
    Setting(
        "levels_from_mm",
        0.0,
        "number",
        "scanning",
        "Bottom level",
        unit="mm",
        lo=0.0,
        hi=1000.0,
        step=0.5,
        help="The last (lowest) level: 0 is the base top, where the part is fully out of the ink.",
    ),
    Setting(
        "step_mode",
        "fixed",
        "choice",
        "scanning",
        "Step mode",
        choices=("fixed", "adaptive"),
        help="`fixed` steps by `level_step_mm`; `adaptive` goes finer where the waterline changes fast "
        "and coarser where it hardly moves.",
    ),
    Setting(
        "level_step_mm",
        0.5,
        "number",
        "scanning",
        "Level step",
        unit="mm",
        lo=0.0,
        hi=100.0,
        lo_ok=False,
        step=0.1,
        help="The step between levels (fixed mode), and the first step of an adaptive scan. Smaller "
        "steps follow steep and detailed parts better and take longer.",
    ),
    Setting(
        "step_min_mm",
        0.1,
        "number",
        "scanning",
        "Smallest adaptive step",
        unit="mm",
        lo=0.0,
        hi=100.0,
        lo_ok=False,
        step=0.05,
        help="The smallest step an adaptive scan takes.",
    ),
    Setting(
        "step_max_mm",
        2.0,
        "number",
        "scanning",
        "Largest adaptive step",
        unit="mm",
        lo=0.0,
        hi=100.0,
        lo_ok=False,
        step=0.1,
        help="The largest step an adaptive scan takes.",
    ),
    Setting(
        "adaptive_change",
        0.02,
        "number",
        "scanning",
        "Adaptive target",
        unit="fraction",
        lo=0.0,
        hi=1.0,
        lo_ok=False,
        step=0.005,
        help="What an adaptive scan aims at: the fraction of the part's outline that moves from "
        "one frame to the next.",
    ),
    Setting(
        "refine_mm",
        0.1,
        "number",
        "scanning",
        "Refine faces to",
        unit="mm",
        lo=0.0,
        hi=100.0,
        step=0.05,
        help="When a flat face comes out of the ink all at once between two levels, the scan goes back "
        "into that step and bisects it until the face's level is known to this (a few extra frames "
        "per face). 0 turns it off: such a face is then known only to within the level step.",
    ),
    Setting(
        "min_free_mb",
        200.0,
        "number",
        "scanning",
        "Keep free on disk",
        unit="MB",
        lo=50.0,
        hi=1e6,
        step=50,
        help="A scan stops (keeping its frames) before the data disk has less than this free.",
    ),
    Setting(
        "auto_resume",
        False,
        "bool",
        "scanning",
        "Resume after a power cut",
        help="Resume a scan that a power cut or crash interrupted as soon as the daemon starts again.",
    ),
    Setting(
        "pipeline",
        "",
        "choice",
        "scanning",
        "Processing",
        choices=pipelines,
        help="Which processing a finished scan gets: empty for ours, `seed` for the dissertation's "
        "(faster, much less accurate).",
    ),
    Setting(
        "method",
        "",
        "choice",
        "scanning",
        "Surface method",
        choices=surface_methods,
        help="The surface method: empty for the pipeline's own (`fit` for ours, `lsq3` for the "
        "dissertation's), or another one to compare (the dissertation's methods run on our waterlines).",
    ),
    Setting(
        "grid",
        50,
        "int",
        "scanning",
        "Height map cells",
        unit="cells a side",
        lo=3,
        hi=2000,
        step=1,
        help="Cells a side of the height map written to heightmap.csv.",
    ),
    # -- the stage (found by commissioning)
    Setting(
        "settle_s",
        0.5,
        "number",
        "stage",
        "Settle time",
        unit="s",
        lo=0.0,
        hi=600.0,
        step=0.1,
        help="Seconds to wait after each move before the frame is taken, for ripples on the ink to die out.",
    ),
    Setting(
        "level_at_home_mm",
        60.0,
        "number",
        "stage",
        "Ink level at home",
        unit="mm",
        lo=0.0,
        hi=1000.0,
        lo_ok=False,
        step=0.01,
        help="The ink's level above the base top with the stage at home. Commissioning measures "
        "it (level zero); every level of a scan is counted from it.",
    ),
    # -- the camera
    Setting(
        "preview_width",
        480,
        "int",
        "camera",
        "Live picture width",
        unit="px",
        lo=64,
        hi=2048,
        step=16,
        help="Width in pixels of the live camera picture on the dashboard.",
    ),
    # -- CAM: the machine and cutter (kept with the job; used by the toolpath stage)
    Setting(
        "scallop_mm",
        0.05,
        "number",
        "cam",
        "Scallop height",
        unit="mm",
        lo=0.0,
        hi=5.0,
        lo_ok=False,
        step=0.005,
        help="The ridge height the finishing program leaves between two passes; the stepover is "
        "chosen for it. Smaller is smoother and slower to compute and to mill.",
    ),
    Setting(
        "cutter_type",
        "ball",
        "choice",
        "cam",
        "Cutter end",
        choices=("ball", "flat"),
        help="The finishing cutter's end: `ball` or `flat`.",
    ),
    Setting(
        "cutter_diameter_mm",
        6.0,
        "number",
        "cam",
        "Cutter diameter",
        unit="mm",
        lo=0.1,
        hi=100.0,
        step=0.1,
        help="The finishing cutter's diameter.",
    ),
    Setting(
        "stepover_mm",
        1.0,
        "number",
        "cam",
        "Stepover",
        unit="mm",
        lo=0.0,
        hi=100.0,
        lo_ok=False,
        step=0.1,
        help="Accepted and checked, not used yet: the stepover follows from `scallop_mm`.",
    ),
    Setting(
        "feed_mm_min",
        800.0,
        "number",
        "cam",
        "Feed",
        unit="mm/min",
        lo=1.0,
        hi=100000.0,
        step=10,
        help="Accepted and checked, not used yet: feeds come from the cutter and the material.",
    ),
    Setting(
        "dialect",
        "linuxcnc",
        "choice",
        "cam",
        "G-code dialect",
        choices=dialects,
        help="The controller the G-code is written for (the same ones `inkslice toolpath --dialect` "
        "knows): `linuxcnc`, `grbl`, `mach3`, `fanuc`, or `dissertation` (the dissertation's own "
        "format, without cutter compensation).",
    ),
    Setting(
        "steep_angle_deg",
        50.0,
        "number",
        "cam",
        "Steep wall angle",
        unit="deg",
        lo=5.0,
        hi=85.0,
        step=1,
        help="Steep and shallow finishing runs waterline (constant-height) passes around walls steeper than "
        "this and zig-zag passes on the rest; the two overlap a little at the seam.",
    ),
    Setting(
        "tool_table",
        "T1 flat D6 FL48; T2 ball D6 FL48; T3 ball D2 FL16",
        "text",
        "cam",
        "Tool table",
        pattern=r"[A-Za-z0-9 .:;/]{1,2000}",
        pattern_says="tools like 'T1 flat D6 FL48; T2 ball D6 FL48 wax:F900/P300/S12000' (letters, digits, "
        "spaces and . : ; / only)",
        help="The machine's tools, by the number its controller uses (Tn M6, G43 Hn): type flat, ball or bull, "
        "D diameter, CR corner radius (bull nose), FL flute length, all in mm; after them, per material, "
        "F feed and P plunge in mm/min and S spindle rpm, else the feeds table's figures.",
    ),
    Setting(
        "operations",
        "rough T1, finish T2 steep, rest T3",
        "text",
        "cam",
        "Job operations",
        pattern=r"[A-Za-z0-9 ,]{1,500}",
        pattern_says="operations like 'rough T1, finish T2 steep, rest T3' (letters, digits, spaces, commas)",
        help="What a job's full program does, in order, with tools from the tool table: `rough` (z-level "
        "roughing), `finish` (add `steep` for waterlines on steep walls), `rest` (a smaller tool only where "
        "the one before could not reach). Used when a job is posted again with its operations.",
    ),
    Setting(
        "envelope_x_mm",
        200.0,
        "number",
        "cam",
        "Machine X travel",
        unit="mm",
        lo=1.0,
        hi=10000.0,
        step=1,
        help="Accepted and checked, not used yet (the machine's X travel).",
    ),
    Setting(
        "envelope_y_mm",
        150.0,
        "number",
        "cam",
        "Machine Y travel",
        unit="mm",
        lo=1.0,
        hi=10000.0,
        step=1,
        help="Accepted and checked, not used yet (the machine's Y travel).",
    ),
    Setting(
        "envelope_z_mm",
        60.0,
        "number",
        "cam",
        "Machine Z travel",
        unit="mm",
        lo=1.0,
        hi=10000.0,
        step=1,
        help="The machine's Z travel; the top level of a scan may not exceed it.",
    ),
    # -- network: where the box tells someone a job ended (daemon/webhook.py)
    Setting(
        "webhook_url",
        "",
        "text",
        "network",
        "Webhook address",
        pattern=URL,
        pattern_says="an http:// or https:// address without spaces (or empty to switch it off)",
        help="The box POSTs a JSON message here when a job finishes, fails or needs attention "
        "(ntfy, Home Assistant or a Telegram bridge take it). Empty: no webhook.",
    ),
    # -- security
    Setting(
        "webhook_token",
        "",
        "text",
        "security",
        "Webhook token",
        pattern=r"[!-~]{1,200}",
        secret=True,
        pattern_says="printable characters without spaces, at most 200 (or empty for none)",
        help="Sent with every webhook as `Authorization: Bearer TOKEN`, for receivers that want one. "
        "Kept out of support bundles.",
    ),
)
BY_KEY = {s.key: s for s in SCHEMA}
assert len(BY_KEY) == len(SCHEMA), "a setting is defined twice"

# The views older code reads (and tests, benches, the docs generator): all derived from SCHEMA.
DEFAULTS = {s.key: s.default for s in SCHEMA}
HELP = {s.key: s.help for s in SCHEMA}
CHOICES = {s.key: s.choices for s in SCHEMA if s.kind == "choice" and not callable(s.choices)}
BOOLS = {s.key for s in SCHEMA if s.kind == "bool"}
INTS = {s.key: (s.lo, s.hi) for s in SCHEMA if s.kind == "int"}
# (lowest, highest, whether the lowest itself is allowed): what a bench box can do.
# A setting outside is a typo or an attack, and a disk-space floor of 0 is no floor.
RANGES = {s.key: (s.lo, s.hi, s.lo_ok) for s in SCHEMA if s.kind == "number"}
SECRETS = {s.key for s in SCHEMA if s.secret}
MAX_LEVELS = 5000


def _check_value(key, value):
    s = BY_KEY[key]
    if s.kind == "choice":
        allowed = s.allowed()
        if value not in allowed:
            named = ", ".join(c for c in allowed if c)
            empty = " (or empty for the default)" if "" in allowed else ""
            raise SettingError(key, f"must be one of {named}{empty}, got {value!r}")
        return value
    if s.kind == "bool":
        if not isinstance(value, bool):
            raise SettingError(key, f"must be true or false, got {value!r}")
        return value
    if s.kind == "text":
        if not isinstance(value, str) or (value and not re.fullmatch(s.pattern, value)):
            raise SettingError(key, f"must be {s.pattern_says}, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SettingError(key, f"must be a number, got {value!r}")
    if s.kind == "int":
        if int(value) != value or not s.lo <= value <= s.hi:
            raise SettingError(key, f"must be a whole number in {s.lo}..{s.hi}, got {value!r}")
        return int(value)
    lo, hi, lo_ok = s.lo, s.hi, s.lo_ok
    if not ((value >= lo if lo_ok else value > lo) and value <= hi):
        if lo == 0 and not lo_ok and value <= 0:
            raise SettingError(key, f"must be positive, got {value!r}")
        raise SettingError(
            key, f"must be {'at least' if lo_ok else 'more than'} {lo:g} and at most {hi:g}, got {value!r}"
        )
    return float(value)


def parse_text(key: str, text: str):
    """A value typed on a command line, read the way the web's JSON would carry it.

    `5` is 5, `true` is true, `grbl` is "grbl": so `inkslice settings set` and the web form
    hand validate() the same value and get the same refusal."""
    import json

    if key in BY_KEY and BY_KEY[key].kind in ("choice", "text"):
        return text
    try:
        return json.loads(text)
    except ValueError:
        return text


def schema_json() -> dict:
    """The schema as the web form and `inkslice settings schema` show it."""
    groups = []
    for gid, title in GROUPS:
        items = []
        for s in SCHEMA:
            if s.group != gid:
                continue
            item = {
                "key": s.key,
                "kind": s.kind,
                "label": s.label,
                "help": s.help,
                "unit": s.unit,
                "default": s.default,
            }
            if s.kind in ("number", "int"):
                item.update(min=s.lo, max=s.hi, min_allowed=s.lo_ok, step=s.step)
            if s.kind in ("choice", "bool"):
                item["choices"] = list(s.allowed())
            if s.kind == "text":
                item.update(pattern=s.pattern, rule=s.pattern_says, secret=s.secret)
            items.append(item)
        groups.append({"id": gid, "title": title, "settings": items})
    return {"groups": groups}


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
        raise SettingError(
            "levels_to_mm",
            f"the top level {new['levels_to_mm']} must be above the bottom level {new['levels_from_mm']}",
        )
    if new["levels_to_mm"] > new["level_at_home_mm"]:
        raise SettingError(
            "levels_to_mm",
            f"{new['levels_to_mm']} mm is above the level with the stage at "
            f"home ({new['level_at_home_mm']} mm): the stage cannot go below home",
        )
    if new["levels_to_mm"] > new["envelope_z_mm"]:
        raise SettingError("levels_to_mm", "above the machine envelope's Z travel")
    if "tool_table" in changes or "operations" in changes:
        # the tools and the operations naming them, checked together (numbers, types, order)
        from ..cam.operations import parse_operations
        from ..cam.tools import parse_tool_text

        parse_operations(new["operations"], parse_tool_text(new["tool_table"]))
    if new["step_min_mm"] > new["step_max_mm"]:
        raise SettingError("step_min_mm", "must not exceed step_max_mm")
    smallest = new["level_step_mm"] if new["step_mode"] == "fixed" else new["step_min_mm"]
    n = (new["levels_to_mm"] - new["levels_from_mm"]) / smallest
    if new["step_mode"] == "fixed" and n + 1 > MAX_LEVELS:
        raise SettingError(
            "level_step_mm", f"{int(n) + 1} levels is more than a scan may take ({MAX_LEVELS})"
        )
    return new


def full(settings: dict) -> dict:
    """Stored settings over the defaults (a newer version may add keys)."""
    return {**DEFAULTS, **{k: v for k, v in settings.items() if k in DEFAULTS}}
