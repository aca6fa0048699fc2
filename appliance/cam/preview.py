"""Preview data: a program's moves as compact JSON for the web's 3D view.

A browser draws a toolpath as line strips, so the moves are grouped into
paths: consecutive moves of one kind (rapid or feed) with one tool. Each path
is a flat list of integers, the points in hundredths of a millimetre, the
first absolute and every later one the difference from the one before (a
finishing program is thousands of tiny steps; as deltas they are one or two
digits each). Tool changes are marked where they happen:

    {"format": "inkslice-preview/1", "units": "0.01 mm",
     "tools": {"2": {"name": "ball6", "diameter": 6.0}},
     "paths": [{"tool": 2, "kind": "rapid", "d": [x0, y0, z0, dx1, dy1, dz1, ...]}, ...],
     "changes": [{"path": 0, "tool": 2}, ...],
     "bounds": [[xmin, ymin, zmin], [xmax, ymax, zmax]]}     (mm)

`decode` turns a path back into points in mm (the tests use it; the page's
script does the same sum).
"""

from __future__ import annotations

import json

import numpy as np

from .program import RAPID

FORMAT = "inkslice-preview/1"
SCALE = 100.0  # units per mm


def preview(programs) -> dict:
    """programs: [(Tool or None, Program)] in the order they run."""
    paths: list[dict] = []
    changes: list[dict] = []
    tools: dict[str, dict] = {}
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    last_tool, prev = object(), None
    for tool, prog in programs:
        number = tool.number if tool is not None else 0
        tools[str(number)] = {"name": prog.cutter.name, "diameter": prog.cutter.diameter}
        if number != last_tool:
            changes.append({"path": len(paths), "tool": number})
            last_tool = number
        xyz = prog.xyz.copy()
        if prev is not None and np.isnan(xyz[0, :2]).any():
            xyz[0, :2] = prev[:2]
        lo, hi = np.minimum(lo, np.nanmin(xyz, axis=0)), np.maximum(hi, np.nanmax(xyz, axis=0))
        kind = prog.kind
        edges = np.flatnonzero(np.diff(kind)) + 1
        for a, b in zip(np.concatenate([[0], edges]), np.concatenate([edges, [kind.size]])):
            # each path starts where the move before it ended
            start = xyz[a - 1] if a > 0 else (prev if prev is not None else xyz[0])
            pts = np.vstack([start[None, :], xyz[a:b]])
            q = np.rint(pts * SCALE).astype(np.int64)
            d = np.vstack([q[:1], np.diff(q, axis=0)])
            paths.append(
                {"tool": number, "kind": "rapid" if kind[a] == RAPID else "feed", "d": d.ravel().tolist()}
            )
        prev = xyz[-1]
    return {
        "format": FORMAT,
        "units": "0.01 mm",
        "tools": tools,
        "paths": paths,
        "changes": changes,
        "bounds": [np.round(lo, 3).tolist(), np.round(hi, 3).tolist()],
    }


def preview_json(programs) -> str:
    return json.dumps(preview(programs), separators=(",", ":"))


def decode(path: dict) -> np.ndarray:
    """(k, 3) points in mm of one path."""
    d = np.asarray(path["d"], np.int64).reshape(-1, 3)
    return np.cumsum(d, axis=0) / SCALE
