"""The JSON API under /api/ about the bench itself: its state and live view, scans, the
machine panel, settings, calibration and commissioning (see static/openapi.json). The other
routes under /api/ are grouped by subject in jobs.py, uploads.py, account.py and system.py;
what they share (errors, id checks) is in apicore.py.

Every route here is behind the login gate in app.py (session cookie + CSRF,
or an API token), except /api/health and /api/openapi.json.
"""

from __future__ import annotations

import json
import time

from flask import Blueprint, Response, current_app, jsonify, request

from .adapter import ACTIVE
from .apicore import check_job_id, check_steps, err, ext, json_body, json_download, json_errors, svc

bp = json_errors(Blueprint("api", __name__))


# -- public ---------------------------------------------------------------------------


@bp.get("/health")
def health():
    return jsonify(ok=True)


@bp.get("/openapi.json")
def openapi():
    return current_app.send_static_file("openapi.json")


# -- state and live view ------------------------------------------------------------------


def state_dict():
    st = svc().state()
    st["eta_display_s"] = ext()["eta"].update(st)
    return st


@bp.get("/state")
def state():
    return jsonify(state_dict())


@bp.get("/events")
def events():
    """Server-Sent Events: `state` on every change, `frame` when a new camera frame exists.

    The stream polls the service every 0.25 s (cheap: a dict copy) rather than
    holding a daemon subscription, and ends after sse_max_s; EventSource then
    reconnects on its own (`retry: 1000`). Phones that sleep thus never pin a
    server thread for long.
    """
    max_s = float(ext()["config"]["sse_max_s"])
    service = svc()
    smoother = ext()["eta"]
    slots = ext()["streams"]
    # Each open stream holds one of waitress's threads. Past max_streams the answer is 503 at
    # once: EventSource gives up and the page polls /api/state instead, so thirty phones on
    # the dashboard cannot starve everyone else's requests.
    if not slots.acquire(blocking=False):
        return err("too many live streams; poll /api/state instead", 503)

    # waitress tells us when the phone has gone (needs channel_request_lookahead, see limits.py),
    # so a closed tab frees its slot within a quarter second, not at the next write
    gone = request.environ.get("waitress.client_disconnected") or (lambda: False)

    def stream():
        try:
            yield from _events(service, smoother, max_s, gone)
        finally:
            slots.release()

    # no stream_with_context: the body needs nothing from the request, and holding the request
    # context for 50 s would only pin memory
    resp = Response(stream(), mimetype="text/event-stream")
    resp.headers["Cache-Control"] = "no-store"
    resp.headers["X-Accel-Buffering"] = "no"
    return resp


def _events(service, smoother, max_s, gone=lambda: False):
    """The stream's body: `state` on every change, `frame` on a new frame, a comment every 15 s."""
    yield "retry: 1000\n\n"
    end = time.monotonic() + max_s
    last_state = last_frame = None
    beat = time.monotonic()
    while time.monotonic() < end and not gone():
        st = service.state()
        st["eta_display_s"] = smoother.update(st)
        key = json.dumps({k: v for k, v in st.items() if k != "eta_display_s"}, sort_keys=True, default=str)
        if key != last_state:
            last_state = key
            yield f"event: state\ndata: {json.dumps(st, default=str)}\n\n"
            beat = time.monotonic()
        fr = service.latest_frame()
        ftime = fr[1].get("time") if fr else None
        if ftime != last_frame:
            last_frame = ftime
            yield f"event: frame\ndata: {json.dumps(_frame_meta(fr[1]) if fr else None)}\n\n"
        if time.monotonic() - beat > 15:
            yield ": keep-alive\n\n"
            beat = time.monotonic()
        time.sleep(0.25)


def _frame_meta(meta):
    return {k: v for k, v in meta.items() if isinstance(v, (int, float, str, type(None)))}


@bp.get("/frame.jpg")
def frame():
    """The last camera frame (waterline drawn by the daemon). Behind the login like everything."""
    got = svc().latest_frame()
    if got is None:
        return Response(status=204)  # no frame yet: not an error a browser should log
    data, meta = got
    etag = f'"{hash((meta.get("time"), len(data))) & 0xFFFFFFFF:08x}"'
    if request.headers.get("If-None-Match") == etag:
        return Response(status=304, headers={"ETag": etag})
    resp = Response(data, mimetype="image/jpeg")
    resp.headers["ETag"] = etag
    resp.headers["Cache-Control"] = "no-cache, private"
    if meta.get("level_mm") is not None:
        resp.headers["X-Level-mm"] = str(meta["level_mm"])
    return resp


@bp.get("/heightmap/live")
def live_heightmap():
    hm = svc().live_heightmap()
    if hm is None:
        return Response(status=204)
    return jsonify(hm)


# -- scans ---------------------------------------------------------------------------


@bp.post("/scan")
def start_scan():
    params = json_body()
    if svc().state().get("state") in ACTIVE:
        return err("a scan is running; stop it first", 409, "scan")
    job_id = svc().start_scan(params)
    return jsonify(job_id=job_id), 201


@bp.post("/scan/cancel")
def cancel_scan():
    svc().cancel()
    return jsonify(state_dict())


@bp.post("/jobs/<job_id>/resume")
def resume(job_id):
    check_job_id(job_id)
    if svc().state().get("state") in ACTIVE:
        return err("a scan is running; stop it first", 409, "scan")
    return jsonify(job_id=svc().resume(job_id)), 201


# -- routes that are one facade call, answered with what it returns ------------------------
# (endpoint, HTTP methods, rule, the call on the service). The machine panel's moves are refused
# (409) by the daemon while a scan, calibration or commissioning holds the bench; the
# commissioning's shapes are in docs/api/README.md (daemon/commissioning.py).
ONE_CALL = (
    ("machine_preview", ["POST"], "/machine/preview", lambda s: s.preview()),
    ("machine_home", ["POST"], "/machine/home", lambda s: s.home_stage()),
    ("machine_jog", ["POST"], "/machine/jog", lambda s: s.jog(json_body().get("mm"))),
    ("machine_goto", ["POST"], "/machine/goto", lambda s: s.goto_level(json_body().get("level_mm"))),
    ("get_settings", ["GET"], "/settings", lambda s: s.settings()),
    ("patch_settings", ["PATCH", "POST"], "/settings", lambda s: s.update_settings(json_body())),
    ("calibration", ["GET"], "/calibration", lambda s: s.calibration()),
    ("commissioning", ["GET"], "/commissioning", lambda s: s.commissioning()),
    (
        "commissioning_import",
        ["POST"],
        "/commissioning/import",
        lambda s: s.import_commissioning(json_body()),
    ),
    ("commissioning_ink_changed", ["POST"], "/commissioning/ink-changed", lambda s: s.ink_changed()),
)


def _answer(call):
    return lambda: jsonify(call(svc()))


for _endpoint, _methods, _rule, _call in ONE_CALL:
    bp.add_url_rule(_rule, _endpoint, _answer(_call), methods=_methods)


@bp.post("/calibration/<step>")
def calibrate(step):
    check_steps(step)
    return jsonify(svc().calibrate(step))


@bp.get("/commissioning/export")
def commissioning_export():
    return json_download(svc().export_commissioning(), "commissioning")


@bp.post("/commissioning/<step>/<action>")
def commission(step, action):
    check_steps(step, action)
    return jsonify(svc().commission(step, action, json_body()))
