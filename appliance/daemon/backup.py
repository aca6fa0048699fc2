"""Backup and restore of what makes a box this box: its settings and its calibration history.

A backup is one JSON document (FORMAT) holding the stored settings and every calibration record
(commissioning results, guided calibrations, ink changes) with its date. Restoring it on another
data folder, or on this one after a fresh install, gives the same settings and the same calibration
in force. Jobs and their files are not in it (they are large and each job keeps its own copy of
the settings and calibration it used).

A restore is checked whole before anything is written (every setting through settings.validate,
every record a dated object), then the settings and the history are replaced.
"""

from __future__ import annotations

import math
import time

from .. import __version__
from ..errors import SettingError
from . import settings as S

FORMAT = "inkslice-backup/1"


def backup(store) -> dict:
    return {
        "format": FORMAT,
        "version": __version__,
        "made": time.time(),
        "settings": S.full(store.load_settings()),
        "calibration": store.calibrations(),
    }


def check(doc) -> tuple[dict, list[dict]]:
    """(settings, calibration records) of a backup document, or SettingError naming what is wrong."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SettingError("backup", f'not an InkSlice backup (want "format": "{FORMAT}")')
    stored = doc.get("settings")
    if not isinstance(stored, dict):
        raise SettingError("backup", "its settings are missing")
    # a key this version does not know (a backup from a newer box) is left out, not refused
    known = {k: v for k, v in stored.items() if k in S.DEFAULTS}
    settings = S.validate(S.DEFAULTS, known)
    records = doc.get("calibration")
    if not isinstance(records, list):
        raise SettingError("backup", "its calibration history is missing")
    for i, rec in enumerate(records):
        when = rec.get("time") if isinstance(rec, dict) else None
        if isinstance(when, bool) or not isinstance(when, (int, float)) or not math.isfinite(when):
            raise SettingError("backup", f"calibration record {i} has no date")
    return settings, records


def restore(store, doc) -> dict:
    settings, records = check(doc)
    store.save_settings(settings)
    store.replace_calibrations(records)
    store.event(
        None,
        "restore",
        f"settings and {len(records)} calibration records restored from a backup "
        f"made {time.strftime('%Y-%m-%d %H:%M', time.localtime(doc.get('made') or 0))}",
    )
    return {"settings": len(settings), "calibration": len(records)}
