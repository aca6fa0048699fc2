"""What every blueprint of the JSON API shares: the app's service and config, JSON error
replies, and the first checks on what a URL or a body names.

The routes live by subject (api.py: the bench; jobs.py: the job manager and downloads;
uploads.py: a scan zip in; account.py: password and tokens; system.py: the system page).
Each blueprint calls json_errors(bp), so a refusal from the daemon reads the same on every
route: {"error": "...", "where": "..."} with 400 (bad setting or scan), 404 (no such job
or file), 409 (the bench is busy), 501 (the bench service lacks the feature).
"""

from __future__ import annotations

import json
import re
import time

from flask import Response, current_app, jsonify, request

from ..errors import DeviceError, InkSliceError, ScanError, SettingError
from .adapter import NotOffered

# Job ids and file names are single path components of safe characters: no
# slashes, no leading dot, no "..". The service checks again (job_file only
# returns files inside the job's folder); this is the first of two locks.
JOB_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,79}$")
FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
STEP = re.compile(r"^[a-z_]{1,30}$")  # a calibration or commissioning step, or a step's action


def ext():
    return current_app.extensions["inkslice"]


def svc():
    return ext()["service"]


def err(message, code, where=None):
    body = {"error": message}
    if where:
        body["where"] = where
    return jsonify(body), code


class Refused(Exception):
    """A request the web itself turns down (a bad id, a body that is not JSON ...)."""

    def __init__(self, message, code):
        super().__init__(message)
        self.message, self.code = message, code


def check_job_id(job_id):
    if not JOB_ID.match(job_id or ""):
        raise Refused("bad job id", 400)


def check_name(name):
    if not FILE_NAME.match(name or "") or ".." in name:
        raise Refused("bad file name", 400)


def check_steps(*names):
    if not all(STEP.match(name or "") for name in names):
        raise Refused(f"bad {' or '.join(('step', 'action')[: len(names)])} name", 400)


def download(body, mimetype: str, what: str, suffix: str) -> Response:
    """A file the browser saves as inkslice-WHAT-<local date and time>.SUFFIX."""
    stamp = time.strftime("%Y%m%d-%H%M", time.localtime())
    disposition = f'attachment; filename="inkslice-{what}-{stamp}.{suffix}"'
    return Response(body, mimetype=mimetype, headers={"Content-Disposition": disposition})


def json_download(doc: dict, what: str) -> Response:
    return download(json.dumps(doc, indent=2) + "\n", "application/json", what, "json")


def json_body() -> dict:
    data = request.get_json(silent=True)
    if data is None:
        if request.content_length:
            raise Refused("body must be JSON", 400)
        data = {}
    if not isinstance(data, dict):
        raise Refused("body must be a JSON object", 400)
    return data


def json_errors(bp):
    """Answer the web's and the daemon's refusals on bp's routes as JSON errors."""
    bp.register_error_handler(Refused, lambda e: err(e.message, e.code))
    bp.register_error_handler(NotOffered, lambda e: err(e.problem, 501, e.where))
    bp.register_error_handler(SettingError, lambda e: err(e.problem, 400, e.where))
    # an uploaded scan folder refused (bad scan.json, a frame of the wrong size ...)
    bp.register_error_handler(ScanError, lambda e: err(e.problem, 400, e.where))
    bp.register_error_handler(DeviceError, lambda e: err(e.problem, 409, e.where))
    # the facade raises InkSliceError for an unknown job or output name
    bp.register_error_handler(InkSliceError, lambda e: err(e.problem, 404, e.where))
    bp.register_error_handler(KeyError, lambda e: err(f"not found: {e}", 404))
    return bp
