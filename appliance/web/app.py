"""The Flask application factory: create_app(service, config).

`service` is a daemon.facade.Bench (BenchService in-process, or rpc.BenchClient); the web room
calls nothing else (docs/architecture.md). `config` is a plain dict:

  data_dir          folder for the web's own files (web/admin.json, tokens, key); required
  https             True when served over HTTPS: session cookie gets `Secure` (default False)
  session_hours     session lifetime (default 12)
  login_attempts    failed logins allowed per address per window (default 5)
  login_window_s    that window (default 300)
  login_global_attempts failed logins allowed from all addresses together in that window (default 50)
  login_hashes      password checks (32 MiB of scrypt each) running at once; more get 429 (default 2)
  max_upload_bytes  largest accepted upload (default 256 MiB)
  max_unzipped_bytes largest total size an uploaded zip may expand to (default 1 GiB)
  max_frame_pixels  largest frame (width x height) an uploaded scan may hold (default 16 Mpx;
                    the camera makes 2048 x 1536)
  usb               offer USB stick export on the job page (default True; the daemon finds the
                    sticks and does the copy, see BenchService.export_to_usb); False hides it
  sse_max_s         how long one Server-Sent-Events connection stays open (default 50 s;
                    the browser reconnects by itself, and a bounded stream keeps waitress's
                    threads from being held forever by phones that went to sleep)
  max_streams       live-event streams open at once (default 8; waitress has 24 threads);
                    past that /api/events answers 503 and the page falls back to polling
  trusted_proxy     True when one reverse proxy fronts the box: the client address is then the
                    right-most X-Forwarded-For entry, the one the proxy appended (default False)
  reset_password    True to replace the admin password by a fresh generated one at start
                    (the demo does, so it can always print one); other sessions end
  bench_data_dir    the daemon's data folder (default: data_dir; the two units share
                    /var/lib/inkslice): a generated password is left there for the bench's
                    display (daemon/firstrun.py) and removed at the first login

The first-run password, if one was just made, is in app.config["FIRST_RUN_PASSWORD"].
"""

from __future__ import annotations

import logging
import threading
import time
from datetime import timedelta
from pathlib import Path

from flask import Flask, g, jsonify, redirect, request, session, url_for
from werkzeug.http import parse_cookie

from ..daemon import firstrun
from ..daemon.facade import Bench
from . import account, api, auth, jobs, pages, system, uploads
from .adapter import WebService
from .eta import EtaSmoother
from .report import picture_caption
from .report import readable as readable_statistics
from .sessions import SessionStore

DEFAULTS = {
    "https": False,
    "session_hours": 12,
    "login_attempts": 5,
    "login_window_s": 300.0,
    "login_global_attempts": 50,
    "login_hashes": 2,
    "max_upload_bytes": 256 * 1024 * 1024,
    "max_unzipped_bytes": 1024 * 1024 * 1024,
    "max_frame_pixels": 16 * 1024 * 1024,
    "sse_max_s": 50.0,
    "max_streams": 8,
    "trusted_proxy": False,
    "usb": True,
}

# Paths anyone may fetch: the login page itself, the static assets it needs, a
# liveness probe for systemd/monitoring, and the API's description (not secret).
PUBLIC_ENDPOINTS = {"pages.login", "static", "pages.favicon", "api.health", "api.openapi", "pages.api_docs"}

CSP = (
    "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'"
)


def create_app(service: Bench, config: dict | None = None) -> Flask:
    cfg = dict(DEFAULTS)
    cfg.update(config or {})
    if not cfg.get("data_dir"):
        raise ValueError("config['data_dir'] is required (the web keeps its password hash there)")
    web_dir = Path(cfg["data_dir"]) / "web"

    app = Flask(__name__)
    app.request_class = uploads.UploadRequest
    creds = auth.Credentials(web_dir)
    sessions = SessionStore(web_dir / "sessions.sqlite", float(cfg["session_hours"]) * 3600)
    uploads.clean_incoming(cfg["data_dir"])  # left by a web that was killed mid-upload
    first_password = creds.ensure_admin()
    if first_password is None and cfg.get("reset_password"):
        first_password = creds.reset_generated()
        sessions.revoke_all()
    cfg.setdefault("bench_data_dir", cfg["data_dir"])
    if first_password is not None:
        try:
            firstrun.hand_over(cfg["bench_data_dir"], first_password)  # the daemon shows it
        except OSError as e:
            logging.getLogger("inkslice.web").warning(
                "cannot leave the first-run password for the bench display in %s: %s",
                cfg["bench_data_dir"],
                e,
            )
    app.config.update(
        SECRET_KEY=auth.secret_key(web_dir),
        SESSION_COOKIE_NAME="inkslice_session",
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Strict",
        SESSION_COOKIE_SECURE=bool(cfg["https"]),
        PERMANENT_SESSION_LIFETIME=timedelta(hours=float(cfg["session_hours"])),
        # Werkzeug refuses bigger bodies with 413 before anything is read into memory or disk.
        MAX_CONTENT_LENGTH=int(cfg["max_upload_bytes"]),
        FIRST_RUN_PASSWORD=first_password,
        INKSLICE=cfg,
        TEMPLATES_AUTO_RELOAD=False,
    )
    app.extensions["inkslice"] = {
        "service": WebService(service),
        "creds": creds,
        "limiter": auth.LoginLimiter(
            int(cfg["login_attempts"]),
            float(cfg["login_window_s"]),
            int(cfg["login_global_attempts"]),
            int(cfg["login_hashes"]),
        ),
        "sessions": sessions,
        "may_send_body": lambda cookie, authorization: _logged_in(app, cookie, authorization),
        "eta": EtaSmoother(),
        "streams": threading.BoundedSemaphore(int(cfg["max_streams"])),
        "config": cfg,
        "started": time.time(),
    }
    app.register_blueprint(pages.bp)
    for room in (api, jobs, uploads, account, system):
        app.register_blueprint(room.bp, url_prefix="/api")

    @app.before_request
    def _gate():
        g.auth = None
        ext = app.extensions["inkslice"]
        header = request.headers.get("Authorization", "")
        if header.startswith("Bearer "):
            tok = ext["creds"].token_valid(header[7:].strip())
            if tok is None:
                return _deny("invalid API token")
            g.auth = "token"  # no CSRF for a header a browser never sends on its own
            return None
        if _session_valid(app, session):
            g.auth = "session"
        elif session.get("user"):
            session.clear()  # logged out, expired or revoked elsewhere
        if g.auth is None and request.endpoint not in PUBLIC_ENDPOINTS:
            return _deny("log in first")
        if request.method not in auth.SAFE_METHODS:
            # Even the login form (login CSRF) checks the token.
            given = request.headers.get("X-CSRF-Token") or request.form.get("csrf_token")
            if not auth.csrf_ok(session.get("csrf"), given):
                return _deny("missing or wrong CSRF token", 403)
        return None

    def _deny(why, code=401):
        if request.path.startswith("/api/") or request.method not in auth.SAFE_METHODS:
            return jsonify(error=why), code
        return redirect(
            url_for("pages.login", next=request.full_path if request.query_string else request.path)
        )

    @app.after_request
    def _headers(resp):
        resp.headers.setdefault("Content-Security-Policy", CSP)
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["X-Frame-Options"] = "DENY"
        resp.headers["Referrer-Policy"] = "same-origin"
        if request.path.startswith("/api/") and "Cache-Control" not in resp.headers:
            resp.headers["Cache-Control"] = "no-store"
        return resp

    @app.errorhandler(413)
    def _too_big(e):
        return jsonify(error=f"upload larger than {cfg['max_upload_bytes']} bytes"), 413

    app.add_template_global(readable_statistics, "readable_statistics")  # the job page's report
    app.add_template_global(picture_caption, "picture_caption")

    @app.template_filter("num")
    def _num(v):
        # report statistics come as full-precision floats; a phone screen wants four figures
        if isinstance(v, float):
            return f"{v:.4g}"
        return v

    @app.context_processor
    def _ctx():
        if "csrf" not in session:
            session["csrf"] = auth.new_csrf()
        return {
            "csrf_token": session["csrf"],
            "logged_in": g.get("auth") is not None,
            "must_change": g.get("auth") == "session" and creds.must_change(),
        }

    return app


def _session_valid(app, sess) -> bool:
    ext = app.extensions["inkslice"]
    return (
        sess.get("user") == "admin"
        and sess.get("gen") == ext["creds"].generation()
        and sess.get("t", 0) + app.permanent_session_lifetime.total_seconds() >= time.time()
        and ext["sessions"].valid(sess.get("sid"))
    )


def _logged_in(app, cookie_header: str, authorization: str) -> bool:
    """The request's raw headers carry a live session or a valid API token (limits.py asks this
    before waitress reads a big body, outside any Flask request)."""
    if authorization.startswith("Bearer "):
        return app.extensions["inkslice"]["creds"].token_valid(authorization[7:].strip()) is not None
    value = parse_cookie(cookie_header).get(app.config["SESSION_COOKIE_NAME"])
    if not value:
        return False
    serializer = app.session_interface.get_signing_serializer(app)
    try:
        sess = serializer.loads(value, max_age=int(app.permanent_session_lifetime.total_seconds()))
    except Exception:  # itsdangerous: bad signature, expired, garbage
        return False
    return isinstance(sess, dict) and _session_valid(app, sess)
