"""The settings' schema: every setting the box has, as data (settings.py checks and stores them).

Each setting is a `Setting`: its type, unit, range or choices, a plain label, the sentence that
explains it and the group it sits in on the web form. A new setting is one entry in SCHEMA;
validation, the web form, `inkslice settings` and docs/settings.md follow from it. A setting
nothing reads does not belong here: it would be a promise the box does not keep.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

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
# what a step between two levels may be, fixed or adaptive: more than nothing, at most 100 mm
LEVEL_STEP: dict = {"unit": "mm", "lo": 0.0, "hi": 100.0, "lo_ok": False}
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
        **LEVEL_STEP,
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
        **LEVEL_STEP,
        step=0.05,
        help="The smallest step an adaptive scan takes.",
    ),
    Setting(
        "step_max_mm",
        2.0,
        "number",
        "scanning",
        "Largest adaptive step",
        **LEVEL_STEP,
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
        help="Which processing a finished scan gets: empty for ours, `seed` for the seed method, the "
        "dissertation's (faster, much less accurate).",
    ),
    Setting(
        "method",
        "",
        "choice",
        "scanning",
        "Surface method",
        choices=surface_methods,
        help="The surface method: empty for the pipeline's own (`fit` for ours, `lsq3` for the "
        "seed method), or another one to compare (the seed method's surface methods run on our waterlines).",
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
