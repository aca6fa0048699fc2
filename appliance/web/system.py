"""The system page's API: the box's figures, its logs, a support bundle, backup and restore, and
the settings schema the settings form is drawn from.

    GET  /api/settings/schema   groups of settings with type, unit, range or choices, help (settings.py)
    GET  /api/system            version, uptimes, the data disk, the last webhook delivery
    GET  /api/logs/<daemon|web> the last 1,000 lines as text (?download=1: as a file)
    GET  /api/support.zip       logs, settings, calibration, system figures, events; no secrets
    GET  /api/backup            settings and calibration history as one JSON file (daemon/backup.py)
    POST /api/restore           that file back (JSON body); refused while the bench works
    POST /api/webhook/test      a test message to the webhook address now: {"ok", "problem"}

Behind the login gate like the rest of /api/ (app.py).
"""

from __future__ import annotations

import io
import json
import logging
import time
import zipfile
from urllib.parse import urlsplit

from flask import Blueprint, Response, jsonify, request

from .. import __version__, logfiles
from ..daemon import settings as S
from .apicore import download, ext, json_download, json_errors, svc

bp = json_errors(Blueprint("system", __name__))
log = logging.getLogger("inkslice.web")


def _bench_data():
    return ext()["config"].get("bench_data_dir") or ext()["config"]["data_dir"]


@bp.get("/settings/schema")
def schema():
    return jsonify(S.schema_json())


def system_info() -> dict:
    info = {
        "version": __version__,
        "web_started": ext()["started"],
        "web_uptime_s": round(time.time() - ext()["started"], 1),
    }
    info.update(svc().system())
    return info


@bp.get("/system")
def system():
    return jsonify(system_info())


@bp.get("/logs/<name>")
def logs(name):
    if name not in logfiles.NAMES:
        return jsonify(error=f"no log named {name!r}; there are {', '.join(logfiles.NAMES)}"), 404
    text = logfiles.tail(_bench_data(), name)
    if request.args.get("download") == "1":
        return download(text, "text/plain; charset=utf-8", name, "log")
    return Response(text, mimetype="text/plain; charset=utf-8")


def without_secrets(settings: dict) -> dict:
    """Settings fit for a support bundle: secret ones blanked, an address cut to its host (an
    ntfy topic or a Home Assistant webhook id in the path is as good as a password)."""
    out = {}
    for key, value in settings.items():
        if key in S.SECRETS:
            out[key] = "(set)" if value else ""
        elif key == "webhook_url" and value:
            u = urlsplit(value)
            out[key] = f"{u.scheme}://{u.hostname}/..."
        else:
            out[key] = value
    return out


@bp.get("/support.zip")
def support_bundle():
    bench = svc()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name in logfiles.NAMES:
            z.writestr(f"logs/{name}.log", logfiles.tail(_bench_data(), name))
        z.writestr("settings.json", json.dumps(without_secrets(bench.settings()), indent=2))
        z.writestr("system.json", json.dumps(system_info(), indent=2, default=str))
        z.writestr("calibration.json", json.dumps(bench.backup()["calibration"], indent=2))
        z.writestr("events.json", json.dumps(bench.events(None, 500), indent=2, default=str))
        z.writestr(
            "README.txt",
            "InkSlice support bundle: the daemon's and web's last log lines, the settings "
            "(secrets left out), the calibration history, the box's figures and its recent "
            "events. No passwords, tokens, scans or jobs.\n",
        )
    return download(buf.getvalue(), "application/zip", "support", "zip")


@bp.get("/backup")
def backup():
    doc = svc().backup()
    log.info("backup of settings and calibration downloaded")
    return json_download(doc, "backup")


@bp.post("/restore")
def restore():
    doc = request.get_json(silent=True)
    if not isinstance(doc, dict):
        return jsonify(error="send the backup file's JSON as the body", where="restore"), 400
    out = svc().restore(doc)
    log.info("settings and calibration restored from a backup: %s", out)
    return jsonify(out)


@bp.post("/webhook/test")
def webhook_test():
    return jsonify(svc().test_webhook())
