"""The HTML pages. They are thin: the data comes from /api/ through static/app.js,
so a page and a script see the same thing."""

from __future__ import annotations

import json
import time
from pathlib import Path
from urllib.parse import urlparse

from flask import Blueprint, current_app, redirect, render_template, request, session, url_for

from ..daemon.settings import schema_json
from ..errors import InkSliceError
from ..vision.printboard import PRINTED, describe
from . import auth
from .apicore import FILE_NAME, JOB_ID
from .jobs import download_name
from .system import system_info

bp = Blueprint("pages", __name__)


def _ext():
    return current_app.extensions["inkslice"]


def _safe_next(target):
    # Only a local path: an open redirect after login is a phishing gift.
    if not target:
        return url_for("pages.dashboard")
    u = urlparse(target)
    if u.scheme or u.netloc or not target.startswith("/") or target.startswith("//"):
        return url_for("pages.dashboard")
    return target


@bp.route("/login", methods=["GET", "POST"])
def login():
    error = None
    code = 200
    if request.method == "POST":
        who = auth.client_address()
        ext = _ext()
        ok, wait = auth.checked_password(ext["limiter"], ext["creds"], who, request.form.get("password", ""))
        if ok is None:
            error = f"Too many failed attempts. Try again in {int(wait) + 1} s."
            resp = current_app.make_response((render_template("login.html", error=error), 429))
            resp.headers["Retry-After"] = str(int(wait) + 1)
            return resp
        if ok:
            session.clear()  # a fresh session (and CSRF token) at every login
            session.permanent = True
            session.update(
                user="admin",
                gen=ext["creds"].generation(),
                sid=ext["sessions"].open(),
                t=time.time(),
                csrf=auth.new_csrf(),
            )
            auth.first_login_done(ext["config"])
            return redirect(_safe_next(request.form.get("next")))
        error, code = "Wrong password.", 401
    return render_template("login.html", error=error, next=request.args.get("next", "")), code


@bp.post("/logout")
def logout():
    _ext()["sessions"].revoke(session.get("sid"))  # a copy of the cookie stops working too
    session.clear()
    return redirect(url_for("pages.login"))


@bp.get("/")
def dashboard():
    svc = _ext()["service"]
    return render_template("dashboard.html", page="dashboard", defaults=svc.settings())


@bp.get("/jobs")
def jobs():
    svc = _ext()["service"]
    sizes = svc.job_sizes()
    return render_template(
        "jobs.html", page="jobs", jobs=[_listed(j, sizes.get(j["id"])) for j in svc.jobs()]
    )


def _listed(job: dict, size) -> dict:
    """A job as the list shows it: its date, how long it took, its size on disk."""
    out = dict(job)
    created, started, finished = job.get("created"), job.get("started"), job.get("finished")
    out["when"] = time.strftime("%d %b %Y, %H:%M", time.localtime(created)) if created else ""
    out["took"] = _duration(finished - started) if started and finished and finished >= started else ""
    out["size"] = _bytes(size) if size is not None else ""
    return out


def _duration(s: float) -> str:
    s = int(round(s))
    return (
        f"{s // 3600} h {s % 3600 // 60:02d} min"
        if s >= 3600
        else (f"{s // 60} min {s % 60:02d} s" if s >= 60 else f"{s} s")
    )


def _bytes(n: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


@bp.get("/jobs/<job_id>")
def job(job_id):
    if not JOB_ID.match(job_id):
        return "bad job id", 400
    svc = _ext()["service"]
    info = svc.job(job_id)
    outputs = [n for n in info.get("outputs", []) if FILE_NAME.match(n)]
    report = None
    if "report.json" in outputs:
        try:
            report = json.loads(svc.job_file(job_id, "report.json").read_text())
        except (OSError, ValueError):
            report = None
    gcode = [n for n in outputs if n.rsplit(".", 1)[-1] in ("gcode", "nc", "ngc", "tap")]
    images = [n for n in outputs if n.endswith(".png")]
    sizes = svc.job_sizes()
    return render_template(
        "job.html",
        page="job",
        job=_listed(info, sizes.get(job_id)),
        outputs=outputs,
        report=report,
        gcode=gcode,
        images=images,
        names={n: download_name(info, n) for n in outputs},
        choices=_choices(),
        repost="heightmap.csv" in outputs and info.get("status") == "done",
        materials=_materials(),
    )


def _materials() -> tuple:
    from ..cam.feeds import MATERIALS

    return tuple(MATERIALS)


def _choices() -> dict:
    """The settings' fixed choices, for the re-process form's selects."""
    from ..daemon import settings as S

    out = {}
    for key in ("cutter_type", "dialect"):
        choices = getattr(S.BY_KEY.get(key), "choices", None) if hasattr(S, "BY_KEY") else S.CHOICES.get(key)
        out[key] = tuple(choices() if callable(choices) else choices or ())
    return out


@bp.get("/settings")
def settings():
    return render_template(
        "settings.html",
        page="settings",
        settings=_ext()["service"].settings(),
        schema=schema_json(),
        tokens=_ext()["creds"].list_tokens(),
    )


@bp.get("/system")
def system():
    return render_template("system.html", page="system", info=system_info())


@bp.get("/calibration")
def calibration():
    return render_template(
        "calibration.html",
        page="calibration",
        board_text=describe(PRINTED),
    )


@bp.get("/commission")
def commission():
    return render_template(
        "commission.html",
        page="commission",
        chessboard=_chessboard_files(),
        board_text=describe(PRINTED),
    )


def _chessboard_files() -> dict:
    """Links to the printable calibration board shipped in static/ (appliance/vision/printboard.py)."""
    static = Path(current_app.static_folder)
    return {
        kind: url_for("static", filename=f"chessboard.{kind}")
        for kind in ("pdf", "png")
        if (static / f"chessboard.{kind}").is_file()
    }


@bp.get("/favicon.ico")
def favicon():
    # what a browser asks for on a page without <link rel="icon"> (the JSON API's, a file view)
    return current_app.send_static_file("favicon.svg")


@bp.get("/api/docs")
def api_docs():
    return render_template("api_docs.html", page="api")


@bp.errorhandler(InkSliceError)
def inkslice_error(e):
    return render_template("error.html", message=str(e)), 404


@bp.app_errorhandler(404)
def not_found(e):
    if request.path.startswith("/api/"):
        return {"error": "not found"}, 404
    return render_template("error.html", message="Not found."), 404
