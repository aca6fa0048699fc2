"""Posting a finished job again for another machine, from its height map.

The scan is the slow part of a job; the height map it left is all a new
program needs. The web's "Post again" form sends a cutter, material, scallop
and dialect (or "with the job's operations": the tool table and operations
from the job's settings), and the box writes the program beside the others,
named for the job, operation, tool and dialect (`<job>-finish-ball6-grbl.nc`,
GRBL one file per tool), with its preview JSON.

The work is `inkslice toolpath JOB_FOLDER ...` in a child process: a finishing
plan takes far more memory than the daemon holds (processing.py explains why
that must not be the daemon's), and the command already names a bad input in
one line, which comes back here as the error.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

from ..errors import InkSliceError, SettingError

TIMEOUT_S = 900.0
OPTIONS = ("dialect", "cutter", "material", "scallop_mm", "steep", "operations")


def check_options(options: dict) -> dict:
    """The form's fields, checked here so a bad one is refused before any work."""
    from ..cam.cutters import parse_cutter
    from ..cam.feeds import DEFAULT_MATERIAL, MATERIALS
    from ..cam.posts import DIALECT_NAMES

    if not isinstance(options, dict):
        raise SettingError("post", "options must be an object")
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise SettingError(unknown[0], f"unknown option (known: {', '.join(OPTIONS)})")
    out = {
        "dialect": options.get("dialect", "linuxcnc"),
        "cutter": str(options.get("cutter", "ball6")),
        "material": options.get("material", DEFAULT_MATERIAL),
        "scallop_mm": options.get("scallop_mm", 0.05),
        "steep": options.get("steep", False),
        "operations": options.get("operations", False),
    }
    if out["dialect"] not in DIALECT_NAMES:
        raise SettingError("dialect", f"must be one of {', '.join(DIALECT_NAMES)}, got {out['dialect']!r}")
    if out["material"] not in MATERIALS:
        raise SettingError("material", f"must be one of {', '.join(MATERIALS)}, got {out['material']!r}")
    parse_cutter(out["cutter"])
    s = out["scallop_mm"]
    if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s) or not 0 < s <= 5:
        raise SettingError("scallop_mm", f"must be a number of mm in (0, 5], got {s!r}")
    for key in ("steep", "operations"):
        if not isinstance(out[key], bool):
            raise SettingError(key, f"must be true or false, got {out[key]!r}")
    return out


def command(job_dir, job_name: str, settings: dict, options: dict) -> list:
    """The child's command line for these (checked) options and the job's settings."""
    o = options
    cmd = [
        sys.executable,
        "-m",
        "appliance.cli",
        "toolpath",
        str(job_dir),
        "--job",
        job_name,
        "--dialect",
        o["dialect"],
        "--material",
        o["material"],
        "--scallop",
        repr(float(o["scallop_mm"])),
        "--steep-angle",
        repr(float(settings.get("steep_angle_deg", 50.0))),
    ]
    if o["operations"]:
        cmd += ["--operations", settings["operations"], "--tools", settings["tool_table"]]
    else:
        cmd += ["--cutter", o["cutter"]] + (["--steep"] if o["steep"] else [])
    return cmd


def repost(job_dir, job_name: str, settings: dict, options: dict) -> list:
    """Write the programs; returns their file names (and their previews') in the job folder."""
    options = check_options(options)
    job_dir = Path(job_dir)
    if not (job_dir / "heightmap.csv").is_file():
        raise SettingError("job", "has no height map to post from (process its scan first)")
    r = subprocess.run(
        command(job_dir, job_name, settings, options),
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        stdin=subprocess.DEVNULL,
    )
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["the toolpath command failed"])[-1]
        problem = last.removeprefix("inkslice: error: ")
        where, _, what = problem.partition(": ")
        raise InkSliceError(where if what else "post", what or problem)
    names = []
    for line in r.stdout.splitlines():
        m = re.match(r"^(.*\.nc): \d+ lines", line)
        if m:
            p = Path(m.group(1))
            names.append(p.name)
            if p.with_suffix(".preview.json").is_file():
                names.append(p.with_suffix(".preview.json").name)
    if not names:
        raise InkSliceError("post", "the toolpath command wrote no program")
    return names
