"""What the bench tells the operator after a front-panel action, as data.

One row per outcome code: the status display's first three lines (16-18
characters fit; the fourth line stays the box's address) and the sentence the
web UI shows and the event log keeps. `{name}` and `{problem}` are filled in.
"""

from __future__ import annotations

import time

WIDTH = 18  # characters render_lines() draws on a line

USB = {
    "copying": (
        ["USB COPY", "copying ...", "do not remove"],
        "copying the latest job's G-code to the USB stick",
    ),
    "copied": (
        ["USB COPY OK", "{name}", "safe to remove"],
        "copied {name} to the USB stick and unmounted it, safe to remove",
    ),
    "still_mounted": (
        ["USB COPY OK", "{name}", "NOT unmounted"],
        "copied {name} to the USB stick and synced it, but could not unmount it ({problem}); "
        "wait until the stick is idle before removing it",
    ),
    "no_stick": (
        ["USB: NO STICK", "plug one in and", "hold again"],
        "USB export: no USB stick is plugged in",
    ),
    "no_gcode": (
        ["USB: NOTHING", "no finished job", "with G-code yet"],
        "USB export: no finished job with G-code to copy",
    ),
    "busy": (["USB COPY", "already copying", ""], "USB export: a copy is already running"),
    "off": (["USB: OFF", "export is off", "on this bench"], "USB export is switched off on this bench"),
    "failed": (["USB COPY FAILED", "{problem1}", "{problem2}"], "USB export failed: {problem}"),
}


def usb_notice(code: str, name: str = "", problem: str = "") -> dict:
    """{"kind", "code", "ok", "text", "lines", "time"} for an outcome code of USB."""
    lines, text = USB[code]
    fill = {
        "name": name,
        "problem": problem,
        "problem1": problem[:WIDTH],
        "problem2": problem[WIDTH : 2 * WIDTH],
    }
    return {
        "kind": "usb",
        "code": code,
        "ok": code == "copied",
        "text": text.format(**fill),
        "lines": [line.format(**fill)[:WIDTH] for line in lines],
        "time": time.time(),
    }
