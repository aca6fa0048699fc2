"""The commissioning results a box keeps, and which of them are in force.

Results live in the store's calibration table, each with its date: {"kind": step, "result":
{...}, "method": "measured" | "entered" | "imported"} (a camera result also carries the
"camera" block scan.json takes). The newest result of each kind is the one in force; an
"ink_changed" row dates the moment after which older meniscus and level-zero results are
stale. in_force()/scan_extra() are what the runner writes into every scan.json; the export
document (FORMAT) carries the results in force to another box or back after a reinstall.

The wizard that measures them is commissioning.py; the measurements are measurements.py.
"""

from __future__ import annotations

import time

from ..errors import InkSliceError, SettingError
from ..vision.camera_block import read_camera

FORMAT = "inkslice.commissioning/1"
STEPS = ("level_zero", "camera", "tank", "meniscus")
TITLES = {
    "level_zero": "Level zero",
    "camera": "Camera lens and liquid plane",
    "tank": "Tank area",
    "meniscus": "Meniscus (reference ball)",
}
SHORT = {"level_zero": "LEVEL 0", "camera": "CAMERA", "tank": "TANK", "meniscus": "MENISCUS"}  # display
INK_SENSITIVE = ("level_zero", "meniscus")  # an ink change makes these stale
NEEDS = {  # what a result of each kind must hold
    "level_zero": ("level_at_home_mm",),
    "tank": ("area_mm2",),
    "camera": ("camera",),
    "meniscus": ("capillary_length_mm", "contact_angle_deg"),
}


def date_text(t) -> str | None:
    return time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(t)) if t else None


def kind_of(record: dict) -> str | None:
    if "kind" in record:
        return record["kind"]
    return "camera" if "camera" in record else None  # a guided calibration's row (calibration.py)


def in_force(store) -> dict:
    """{kind: {"date", "result", "method", "stale"}} for each step with a result, and "ink_changed"."""
    out, ink = {}, None
    for rec in store.calibrations():  # newest first
        kind = kind_of(rec)
        if kind == "ink_changed":
            ink = rec["time"] if ink is None else ink
            continue
        if kind not in STEPS or kind in out or rec.get("skipped"):
            continue
        result = rec.get("result") or {}
        if kind == "camera":
            result = {**result, "camera": rec["camera"]}
        out[kind] = {"date": rec["time"], "result": result, "method": rec.get("method", "guided")}
    for kind, entry in out.items():
        entry["stale"] = bool(kind in INK_SENSITIVE and ink is not None and entry["date"] < ink)
    return {**out, "ink_changed": ink}


def scan_extra(store, settings: dict) -> dict:
    """The scan.json keys for the calibration in force: "tank", "meniscus" (what processing
    uses) and "calibration" (what was used, with dates, for the report)."""
    force = in_force(store)
    used = {}
    extra = {}
    if "camera" in force:
        used["camera"] = {"date": force["camera"]["date"], "method": force["camera"]["method"]}
    if "tank" in force:
        area = float(force["tank"]["result"]["area_mm2"])
        falls = bool(force["tank"]["result"].get("surface_falls", True))  # no overflow said: it falls
        extra["tank"] = {"inner_area_mm2": area, "surface_falls": falls}
        used["tank"] = {"date": force["tank"]["date"], "area_mm2": area, "method": force["tank"]["method"]}
    if "meniscus" in force:
        r = force["meniscus"]["result"]
        extra["meniscus"] = {
            "format": "inkslice.meniscus/1",
            "capillary_length_mm": r["capillary_length_mm"],
            "contact_angle_deg": r["contact_angle_deg"],
            "contact_line_curvature": r.get("contact_line_curvature", 0.0),
        }
        used["meniscus"] = {
            "date": force["meniscus"]["date"],
            "method": force["meniscus"]["method"],
            "reference": r.get("reference"),
        }
    at_home = float(settings["level_at_home_mm"])
    lz = force.get("level_zero")
    if lz is not None and abs(float(lz["result"]["level_at_home_mm"]) - at_home) < 1e-6:
        used["level_zero"] = {"date": lz["date"], "level_at_home_mm": at_home, "method": lz["method"]}
    else:
        used["level_zero"] = {"date": None, "level_at_home_mm": at_home, "method": "setting"}
    if force["ink_changed"]:
        used["ink_changed"] = force["ink_changed"]
    extra["calibration"] = used
    return extra


def overview(store) -> tuple[list[dict], dict]:
    """Each step's row for the page ({"id", "title", "status", "result", "method", "date",
    "date_text"}; status done, stale, skipped or missing), and in_force()."""
    force = in_force(store)
    last = {}
    for rec in store.calibrations():
        k = kind_of(rec)
        if k in STEPS and k not in last:
            last[k] = rec
    steps = []
    for k in STEPS:
        entry = force.get(k)
        if entry is not None:
            status = "stale" if entry["stale"] else "done"
        else:
            status = "skipped" if last.get(k, {}).get("skipped") else "missing"
        steps.append(
            {
                "id": k,
                "title": TITLES[k],
                "status": status,
                "result": public(entry["result"]) if entry else None,
                "method": entry["method"] if entry else None,
                "date": entry["date"] if entry else None,
                "date_text": date_text(entry["date"] if entry else None),
            }
        )
    return steps, force


def export_doc(store) -> dict:
    """The results in force as one document (FORMAT), for another box or a reinstall."""
    force = in_force(store)
    return {
        "format": FORMAT,
        "exported": time.time(),
        "results": {
            k: {"date": force[k]["date"], "method": force[k]["method"], "result": force[k]["result"]}
            for k in STEPS
            if k in force
        },
        "ink_changed": force["ink_changed"],
    }


def import_records(store, doc: dict, results: dict) -> None:
    """Store an export's results (checked by check_export) with their own dates."""
    if doc.get("ink_changed"):
        store.add_calibration({"kind": "ink_changed"}, when=doc["ink_changed"])
    for kind, entry in results.items():
        result = dict(entry["result"])
        record = {"kind": kind, "method": entry.get("method", "imported"), "imported": time.time()}
        if kind == "camera":
            record["camera"] = result.pop("camera")
        record["result"] = result
        store.add_calibration(record, when=entry["date"])


def stored_camera(store):
    """The camera block in force (commissioned or guided), or None."""
    force = in_force(store)
    return force["camera"]["result"]["camera"] if "camera" in force else None


def public(result: dict) -> dict:
    """A result as the page shows it: without the camera's matrices."""
    return {k: v for k, v in result.items() if k != "camera"}


def summary(kind, r) -> str:
    if kind == "level_zero":
        return f"base top meets the ink at stage position {r['level_at_home_mm']:.3f} mm"
    if kind == "tank":
        return r["figure"]
    if kind == "meniscus":
        ref = r.get("reference") or {}
        text = f"capillary length {r['capillary_length_mm']:.3f} mm, contact angle {r['contact_angle_deg']:.1f} deg"
        if "mean_abs_error_mm" in ref:
            text += (
                f"; this box measures the {ref['diameter_mm']:g} mm ball to {ref['mean_abs_error_mm']:.3f} mm"
            )
        return text
    if kind == "camera":
        return f"{r.get('mm_per_px')} mm/px, plane RMS {r.get('plane_rms_mm')} mm, lens: {r.get('lens')}"
    return ""


def check_export(doc) -> dict:
    where = "commissioning file"
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SettingError(where, f"not a commissioning export (format {FORMAT!r} expected)")
    results = doc.get("results")
    if not isinstance(results, dict):
        raise SettingError(where, "'results' must be an object of step: result")
    for kind, entry in results.items():
        if kind not in STEPS:
            raise SettingError(where, f"unknown step {kind!r}")
        if (
            not isinstance(entry, dict)
            or not isinstance(entry.get("result"), dict)
            or not isinstance(entry.get("date"), (int, float))
        ):
            raise SettingError(where, f"{kind}: needs a date and a result")
        r = entry["result"]
        for key in NEEDS[kind]:
            if key not in r:
                raise SettingError(where, f"{kind}: {key} is missing")
        if kind == "camera":
            try:
                read_camera(where, r["camera"])
            except InkSliceError as e:
                raise SettingError(where, f"camera: {e.problem}") from None
    ink = doc.get("ink_changed")
    if ink is not None and not isinstance(ink, (int, float)):
        raise SettingError(where, "ink_changed must be a date (seconds) or null")
    return results
