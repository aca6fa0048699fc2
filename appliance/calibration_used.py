"""What calibration a scan was processed with, for the report: named with dates, and warned
about when missing or older than the last ink change.

The daemon writes the calibration in force into scan.json (daemon/commissioning.py
scan_extra): "tank" and "meniscus" (which processing uses) and "calibration" (what was
used and when). A scan rendered or imported from elsewhere may have only some of them.
"""

from __future__ import annotations

import time

STALE_AFTER_INK = ("meniscus", "level_zero")


def _date(t) -> str:
    return time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(t)) if t else "undated"


def describe(scan, displacement=True, meniscus=None) -> dict:
    """{"used": {what: text}, "warnings": [text]} for this scan and these processing options.

    `meniscus`: processing's option (None = scan.json's, False = off, a file or a model)."""
    cal = scan.extra.get("calibration") if isinstance(scan.extra.get("calibration"), dict) else {}
    ink = cal.get("ink_changed")
    used, warnings = {}, []

    def dated(what):
        entry = cal.get(what) or {}
        return f" ({entry.get('method', 'stored')}, {_date(entry.get('date'))})" if entry.get("date") else ""

    if "camera" in cal:
        used["camera"] = "commissioned camera" + dated("camera")
    elif cal:
        used["camera"] = "the bench's own camera model (not commissioned)"
        warnings.append("the camera was not commissioned: the bench's own camera model was used")
    else:
        used["camera"] = "scan.json's camera block"
    tank = scan.tank_area_mm2
    if not displacement:
        used["tank"] = "displacement correction switched off"
    elif tank:
        used["tank"] = f"tank area {float(tank):.0f} mm²" + dated("tank")
    else:
        warnings.append(
            "no tank area calibration was used: the ink's displacement is not corrected "
            "(commission the tank area)"
        )
    if meniscus is False:
        used["meniscus"] = "meniscus correction switched off"
    elif meniscus is not None:
        used["meniscus"] = (
            f"meniscus model from {meniscus}"
            if isinstance(meniscus, (str, bytes)) or hasattr(meniscus, "__fspath__")
            else "meniscus model given to processing"
        )
    elif scan.extra.get("meniscus"):
        m = scan.extra["meniscus"]
        text = (
            f"meniscus: capillary length {float(m['capillary_length_mm']):.3f} mm, contact angle "
            f"{float(m['contact_angle_deg']):.1f} deg" + dated("meniscus")
        )
        ref = (cal.get("meniscus") or {}).get("reference") or {}
        if "mean_abs_error_mm" in ref:
            text += (
                f"; the {ref['diameter_mm']:g} mm ball measured to {ref['mean_abs_error_mm']:.3f} mm with it"
            )
        used["meniscus"] = text
    else:
        warnings.append(
            "no meniscus calibration was used: heights on slopes read low by up to the "
            "ink's capillary rise (commission the meniscus with the reference ball)"
        )
    lz = cal.get("level_zero")
    if lz:
        if lz.get("date"):
            used["level_zero"] = (
                f"level zero at stage position {float(lz['level_at_home_mm']):.3f} mm" + dated("level_zero")
            )
        else:
            used["level_zero"] = (
                f"level zero from the setting level_at_home_mm ({float(lz['level_at_home_mm']):.3f} mm)"
            )
            warnings.append(
                "level zero was not measured: heights rest on the setting level_at_home_mm "
                "(commission level zero)"
            )
    for what in STALE_AFTER_INK:
        date = (cal.get(what) or {}).get("date")
        if ink and date and date < ink and what in used:
            warnings.append(
                f"the {what.replace('_', ' ')} calibration ({_date(date)}) is older than the last "
                f"ink change ({_date(ink)}): measure it again"
            )
    return {"used": used, "warnings": warnings, "ink_changed": ink}


def markdown(info: dict) -> list[str]:
    lines = ["", "## Calibration", ""]
    lines += [f"- {what.replace('_', ' ')}: {text}" for what, text in info["used"].items()]
    if info["warnings"]:
        lines += ["", "Warnings:", ""] + [f"- **{w}**" for w in info["warnings"]]
    return lines
