"""The tool table: the cutters a machine has, by number, with their feeds.

A job that uses several tools (rough with a flat end mill, finish with a
ball, rest-machine with a small ball) names them by their number in this
table; the number is the `T` word of the tool change and the `H` word of
the tool-length offset (G43 Hn), so it must be the number the controller's
own tool table uses for that tool.

A tool is a cutter (cutters.py: type, diameter, corner radius, flute length,
flutes) plus optional feeds per material: {"wax": {"feed_mm_min": 900,
"plunge_mm_min": 300, "rpm": 12000}}. A material the tool has no entry for,
or a missing figure, falls back to the feeds table (feeds.py).

The table is a list of plain dicts (JSON, `inkslice toolpath --tools`);
`parse_tool_table` checks it and names the bad entry and field. The daemon's
settings keep it as one line of text a phone can edit (`tool_table`):

    T1 flat D6 FL48; T2 ball D6 FL48 wax:F900/P300/S12000; T3 ball D2 FL16; T4 bull D6 CR1

(D diameter, CR corner radius, FL flute length, all mm; per material F feed
and P plunge in mm/min, S spindle rpm), read by `parse_tool_text`.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ..errors import SettingError
from .cutters import DEFAULT_FLUTE_FACTOR, Cutter
from .feeds import MATERIALS, Conditions, conditions

TOOL_TYPES = ("flat", "ball", "bull")
FEED_KEYS = ("feed_mm_min", "plunge_mm_min", "rpm")
MAX_TOOL_NUMBER = 99  # Fanuc's and LinuxCNC's usual pocket range

# A bench mill's small set: a flat end mill to rough, a 6 mm ball to finish, a
# 2 mm ball for what the 6 mm cannot reach.
DEFAULT_TOOL_TABLE = [
    {"number": 1, "type": "flat", "diameter_mm": 6.0, "corner_radius_mm": 0.0, "flute_length_mm": 48.0},
    {"number": 2, "type": "ball", "diameter_mm": 6.0, "corner_radius_mm": 3.0, "flute_length_mm": 48.0},
    {"number": 3, "type": "ball", "diameter_mm": 2.0, "corner_radius_mm": 1.0, "flute_length_mm": 16.0},
]


@dataclass(frozen=True)
class Tool:
    number: int
    cutter: Cutter
    feeds: dict = field(default_factory=dict, compare=False, hash=False)

    @property
    def name(self) -> str:
        return self.cutter.name

    def conditions(self, material: str, **override) -> Conditions:
        """The tool's own figures for `material` where it has them, else the feeds table's;
        explicit overrides (feed=, plunge=, rpm=) win over both."""
        own = self.feeds.get(material, {})
        kw = {"feed": own.get("feed_mm_min"), "plunge": own.get("plunge_mm_min"), "rpm": own.get("rpm")}
        kw.update({k: v for k, v in override.items() if v is not None})
        return conditions(self.cutter, material, **kw)

    def describe(self) -> str:
        return f"T{self.number} {self.cutter.describe()}"


def _number(entry, key, where, positive=True):
    v = entry.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise SettingError(where, f"{key} must be a number, got {v!r}")
    if positive and v <= 0:
        raise SettingError(where, f"{key} must be > 0, got {v!r}")
    return float(v)


def parse_tool(entry: dict, where="tool_table") -> Tool:
    if not isinstance(entry, dict):
        raise SettingError(
            where, f"a tool must be an object with number, type, diameter_mm, ..., got {entry!r}"
        )
    known = {"number", "type", "diameter_mm", "corner_radius_mm", "flute_length_mm", "flutes", "feeds"}
    extra = sorted(set(entry) - known)
    if extra:
        raise SettingError(where, f"unknown field {extra[0]!r} (known: {', '.join(sorted(known))})")
    n = entry.get("number")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_TOOL_NUMBER:
        raise SettingError(where, f"number must be a whole number 1..{MAX_TOOL_NUMBER}, got {n!r}")
    where = f"{where} T{n}"
    kind = entry.get("type")
    if kind not in TOOL_TYPES:
        raise SettingError(where, f"type must be one of {', '.join(TOOL_TYPES)}, got {kind!r}")
    d = _number(entry, "diameter_mm", where)
    if kind == "ball":
        rc = d / 2
    elif kind == "flat":
        rc = 0.0
    else:
        rc = _number(entry, "corner_radius_mm", where)
        if rc >= d / 2:
            raise SettingError(
                where, f"a bull nose's corner radius must be less than the radius {d / 2:g} mm"
            )
    if kind != "bull" and "corner_radius_mm" in entry:
        given = _number(entry, "corner_radius_mm", where, positive=False)
        if abs(given - rc) > 1e-9:
            raise SettingError(
                where, f"a {kind} cutter of {d:g} mm has corner radius {rc:g} mm, got {given:g}"
            )
    fl = _number(entry, "flute_length_mm", where) if "flute_length_mm" in entry else DEFAULT_FLUTE_FACTOR * d
    flutes = entry.get("flutes", 2)
    if isinstance(flutes, bool) or not isinstance(flutes, int) or flutes < 1:
        raise SettingError(where, f"flutes must be a whole number >= 1, got {flutes!r}")
    try:
        cutter = Cutter(d, rc, fl, flutes)
    except SettingError as e:
        raise SettingError(where, e.problem) from None
    feeds = entry.get("feeds", {}) or {}
    if not isinstance(feeds, dict):
        raise SettingError(where, f"feeds must be an object of material: figures, got {feeds!r}")
    for material, figs in feeds.items():
        if material not in MATERIALS:
            raise SettingError(
                where, f"feeds for unknown material {material!r} (known: {', '.join(MATERIALS)})"
            )
        if not isinstance(figs, dict) or set(figs) - set(FEED_KEYS):
            raise SettingError(where, f"feeds for {material} must be an object of {', '.join(FEED_KEYS)}")
        for k in figs:
            _number(figs, k, f"{where} {material}")
    return Tool(n, cutter, {m: dict(f) for m, f in feeds.items()})


def parse_tool_table(entries) -> dict:
    """{number: Tool}; every entry checked, numbers unique."""
    if not isinstance(entries, (list, tuple)) or not entries:
        raise SettingError("tool_table", "must be a non-empty list of tools")
    table = {}
    for e in entries:
        t = parse_tool(e)
        if t.number in table:
            raise SettingError("tool_table", f"tool number {t.number} is listed twice")
        table[t.number] = t
    return table


DEFAULT_TOOL_TEXT = "T1 flat D6 FL48; T2 ball D6 FL48; T3 ball D2 FL16"
_TEXT_TOOL = re.compile(
    r"T(\d+)\s+(flat|ball|bull)\s+D(\d+(?:\.\d*)?)(?:\s+CR(\d+(?:\.\d*)?))?"
    r"(?:\s+FL(\d+(?:\.\d*)?))?((?:\s+[a-z]+:[^\s;]+)*)",
    re.I,
)
_TEXT_FEED = re.compile(r"([a-z]+):((?:[FPS]\d+(?:\.\d*)?/?)+)", re.I)


def one_line_items(text: str, sep: str, pattern: re.Pattern, setting: str, form: str) -> Iterator[re.Match]:
    """The items of a one-line list (`text` cut at `sep`, blank items skipped) as matches of
    `pattern`. An item that does not match is refused, quoted, with `form`: how to write one."""
    for part in str(text).split(sep):
        part = part.strip()
        if not part:
            continue
        m = pattern.fullmatch(part)
        if not m:
            raise SettingError(setting, f"{part!r}: {form}")
        yield m


def parse_tool_text(text: str) -> dict:
    """The settings' one-line table ('T1 flat D6 FL48; T2 ball D6 ...') -> {number: Tool}."""
    form = (
        "write a tool as 'T2 ball D6 FL48' (T number, type flat, ball or bull, D diameter, CR corner "
        "radius for a bull nose, FL flute length, mm), then material:F900/P300/S12000 if it has its own feeds"
    )
    entries = []
    for m in one_line_items(text, ";", _TEXT_TOOL, "tool_table", form):
        e = {"number": int(m.group(1)), "type": m.group(2).lower(), "diameter_mm": float(m.group(3))}
        if m.group(4):
            e["corner_radius_mm"] = float(m.group(4))
        if m.group(5):
            e["flute_length_mm"] = float(m.group(5))
        feeds = {}
        for fm in _TEXT_FEED.finditer(m.group(6) or ""):
            names = {"F": "feed_mm_min", "P": "plunge_mm_min", "S": "rpm"}
            feeds[fm.group(1).lower()] = {
                names[w[0].upper()]: float(w[1:]) for w in fm.group(2).split("/") if w
            }
        if feeds:
            e["feeds"] = feeds
        entries.append(e)
    return parse_tool_table(entries)


def tool_entry(tool: Tool) -> dict:
    """The settings form of a tool (inverse of parse_tool)."""
    c = tool.cutter
    e = {
        "number": tool.number,
        "type": c.kind,
        "diameter_mm": c.diameter,
        "corner_radius_mm": c.corner_radius,
        "flute_length_mm": c.flute_length,
    }
    if c.flutes != 2:
        e["flutes"] = c.flutes
    if tool.feeds:
        e["feeds"] = tool.feeds
    return e


def default_tools() -> dict:
    return parse_tool_table(DEFAULT_TOOL_TABLE)
