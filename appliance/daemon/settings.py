"""The daemon's settings: checked, parsed and shown from one schema (settings_schema.py) that the
daemon, the web form, the CLI and the docs all read.

validate() checks changes against the schema, the web form is drawn from schema_json(),
`inkslice settings` parses with parse_text() and checks with the same code, and docs/settings.md
is generated from it (scripts/gen_settings_doc.py). full() reads stored settings: a key this
version no longer has (a setting that was removed, or one from a newer box) is left out with a
note in the log, so an old settings file or job record still loads.

Bench settings (calibration, timing) and per-scan defaults share one flat
namespace; a scan's parameters may override any per-scan key, and the job
keeps its own copy so a resumed scan uses the settings it started with.
"""

from __future__ import annotations

import logging
import math
import re

from ..errors import SettingError
from .settings_schema import GROUPS, KINDS, SCHEMA, Setting, dialects, pipelines, surface_methods

# the schema's names are read through this module (S.SCHEMA, S.GROUPS, ...) as before the split
__all__ = ["GROUPS", "KINDS", "SCHEMA", "Setting", "dialects", "pipelines", "surface_methods"]
log = logging.getLogger("inkslice.settings")

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


_noted: set[str] = set()  # unknown keys already noted in the log (full() runs on every read)


def full(settings: dict) -> dict:
    """Stored settings over the defaults (a newer version may add keys); unknown keys left out."""
    for key in settings.keys() - DEFAULTS.keys() - _noted:
        _noted.add(key)
        log.info("setting %r is not one this version has (removed, or from a newer box): ignored", key)
    return {**DEFAULTS, **{k: v for k, v in settings.items() if k in DEFAULTS}}
