"""Ground truth for scans of known parts: which part a scan shows, kept beside
the scan folder as `<scan>.truth.json` (never inside it, so processing can
never peek). Processing itself only takes a truth object (appliance/process.py);
the commands, the simulated bench, benches and tests find it here.
"""

from __future__ import annotations

import json
from pathlib import Path

from .. import atomicio
from ..errors import ScanError
from . import surfaces


def truth_path(folder) -> Path:
    folder = Path(folder)
    return folder.parent / (folder.name + ".truth.json")


def write_truth(scan_folder, surface_name: str) -> Path:
    """Say which known part a scan folder shows (the simulated bench's scans)."""
    path = truth_path(scan_folder)
    doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    atomicio.write_json(path, {**doc, "surface": surfaces.get(surface_name).name})
    return path


def find_truth(scan_folder, truth=None):
    """The known part for a scan's statistics, or None.

    `truth`: None (the `<scan>.truth.json` beside the folder, when there is one),
    False (none), a surface name, or the path of a truth file.
    """
    if truth is False:
        return None
    if isinstance(truth, str) and truth in surfaces.SURFACES:
        return surfaces.get(truth)
    path = Path(truth) if truth else truth_path(scan_folder)
    if not path.is_file():
        if truth:
            raise ScanError(path, "ground-truth file does not exist")
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        name = doc["surface"]
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError) as e:
        raise ScanError(path, f"not a ground-truth file ({e})") from None
    if name not in surfaces.SURFACES:
        raise ScanError(path, f"unknown surface {name!r}")
    return surfaces.get(name)
