"""The job manager's API under /api/jobs: the list, one job, rename, delete, process again,
a new program for another machine, and the job's files (one by one, as a zip, a thumbnail,
or copied to a USB stick by the daemon).

Downloads are named for their job (download_name), so three jobs' programs in a Downloads
folder are not toolpath.gcode, toolpath (1).gcode ... Behind the login gate (app.py).
"""

from __future__ import annotations

import json
import re
import tempfile
import zipfile
from pathlib import Path

from flask import Blueprint, Response, jsonify, request, send_file

from ..errors import InkSliceError
from .adapter import ACTIVE, NotOffered
from .apicore import FILE_NAME, Refused, check_job_id, check_name, err, ext, json_body, json_errors, svc

bp = json_errors(Blueprint("jobs", __name__))


@bp.get("/jobs")
def jobs():
    sizes = svc().job_sizes()
    return jsonify(jobs=[{**j, "size_bytes": sizes.get(j["id"])} for j in svc().jobs()])


# -- the job manager --------------------------------------------------------------------------


@bp.patch("/jobs/<job_id>")
def rename_job(job_id):
    check_job_id(job_id)
    return jsonify(svc().rename_job(job_id, json_body().get("name", "")))


@bp.delete("/jobs/<job_id>")
def delete_job(job_id):
    check_job_id(job_id)
    svc().delete_job(job_id)
    return jsonify(ok=True)


@bp.post("/jobs/<job_id>/reprocess")
def reprocess_job(job_id):
    check_job_id(job_id)
    if svc().state().get("state") in ACTIVE:
        return err("a scan is running; stop it first", 409, "scan")
    changes = json_body().get("settings") or {}
    if not isinstance(changes, dict):
        raise Refused("settings must be a JSON object", 400)
    return jsonify(job_id=svc().reprocess(job_id, changes)), 202


@bp.post("/jobs/<job_id>/post")
def repost_job(job_id):
    """A new program from the job's height map for another cutter, material, scallop or dialect
    (daemon/repost.py): {dialect, cutter, material, scallop_mm, steep, operations} -> {files}."""
    check_job_id(job_id)
    options = json_body()
    if not isinstance(options, dict):
        raise Refused("the options must be a JSON object", 400)
    return jsonify(files=svc().repost(job_id, options))


@bp.get("/jobs/<job_id>/thumb.png")
def job_thumb(job_id):
    """A small picture of the height map (thumbs.py), for the job list."""
    from .thumbs import thumbnail

    path = _job_path(job_id, "heightmap.csv")
    png = thumbnail(path, Path(ext()["config"]["data_dir"]) / "web" / "thumbs", job_id)
    if png is None:
        return Response(status=204)
    resp = send_file(png, mimetype="image/png", max_age=0)
    resp.headers["Cache-Control"] = "private, no-cache"
    return resp


def download_name(job: dict, name: str) -> str:
    """A download named for its job: "cone-on-the-bench-20261202-155332-toolpath.gcode"."""
    label = re.sub(r"[^A-Za-z0-9]+", "-", str(job.get("name") or "")).strip("-")[:40]
    stamp = "-".join(str(job.get("id", "")).split("-")[:2])
    return "-".join(p for p in (label, stamp, name) if p)


@bp.get("/jobs/<job_id>")
def job(job_id):
    check_job_id(job_id)
    return jsonify(svc().job(job_id))


def _job_path(job_id, name) -> Path:
    check_job_id(job_id)
    check_name(name)
    if name not in svc().job(job_id).get("outputs", []):
        raise Refused(f"job {job_id} has no output {name!r}", 404)
    path = svc().job_file(job_id, name)
    if not path.is_file():
        raise Refused(f"job {job_id} has no output {name!r}", 404)
    return path


TEXT_TYPES = {".gcode", ".nc", ".ngc", ".tap", ".csv", ".md", ".json", ".txt", ".stl"}


@bp.get("/jobs/<job_id>/files/<name>")
def job_file(job_id, name):
    path = _job_path(job_id, name)
    inline = request.args.get("inline") == "1" and path.suffix.lower() in (
        ".png",
        ".jpg",
        ".jpeg",
        ".json",
        ".md",
        ".csv",
        ".gcode",
        ".nc",
        ".ngc",
    )
    mimetype = "text/plain; charset=utf-8" if path.suffix.lower() in TEXT_TYPES - {".json"} else None
    resp = send_file(
        path,
        as_attachment=not inline,
        download_name=download_name(svc().job(job_id), name),
        mimetype=mimetype,
        max_age=0,
    )
    resp.headers["Cache-Control"] = "private, no-cache"
    return resp


SCAN_FILE = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*(/[A-Za-z0-9_-][A-Za-z0-9_.-]*)*$")


def _scan_files(job_id):
    """scan/scan.json and the frames it lists, when the service keeps the scan in the job's folder.

    The facade has no "list the folder" call; scan.json is the scan's own table of contents.
    """
    try:
        doc_path = svc().job_file(job_id, "scan/scan.json")
        doc = json.loads(doc_path.read_text())
    except (InkSliceError, OSError, ValueError):
        return []
    files = [("scan/scan.json", doc_path)]
    for fr in doc.get("frames", []) if isinstance(doc, dict) else []:
        rel = fr.get("file") if isinstance(fr, dict) else None
        if isinstance(rel, str) and SCAN_FILE.match(rel) and ".." not in rel.split("/"):
            try:
                files.append((f"scan/{rel}", svc().job_file(job_id, f"scan/{rel}")))
            except InkSliceError:
                pass
    return files


@bp.get("/jobs/<job_id>/archive.zip")
def job_zip(job_id):
    """The job's outputs and, where the service keeps it, the scan folder (scan.json + frames).

    Written to a temporary file, not memory: a 2048 x 1536 scan is a few hundred MB of PNGs and
    the Pi has 1 GB. Frames are PNGs already, so they are stored, not deflated again.
    """
    check_job_id(job_id)
    info = svc().job(job_id)
    tmp = tempfile.TemporaryFile()
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for name in info.get("outputs", []):
            if FILE_NAME.match(name):
                z.write(svc().job_file(job_id, name), f"{job_id}/{name}")
        for arc, path in _scan_files(job_id):
            z.write(
                path, f"{job_id}/{arc}", compress_type=zipfile.ZIP_STORED if arc.endswith(".png") else None
            )
        z.writestr(f"{job_id}/job.json", json.dumps(info, indent=2, default=str))
    tmp.seek(0)
    return send_file(
        tmp, mimetype="application/zip", as_attachment=True, download_name=download_name(info, "inkslice.zip")
    )


# -- USB stick -----------------------------------------------------------------------------------

# The daemon holds the sticks and does the copy (the web service has no device access).


def _usb_offered() -> bool:
    return bool(ext()["config"].get("usb"))


@bp.get("/usb")
def usb_sticks():
    sticks = svc().usb_sticks() if _usb_offered() else []
    return jsonify(available=bool(sticks), sticks=sticks)


@bp.post("/jobs/<job_id>/usb")
def usb_export(job_id):
    body = json_body()
    name = str(body.get("file") or "toolpath.gcode")
    _job_path(job_id, name)  # a known job and a file name the API serves
    if not _usb_offered():
        raise NotOffered("usb", "USB export is switched off on this box")
    stick = body.get("stick")
    result = svc().export_to_usb(job_id, name, str(stick) if stick else None)  # synced and unmounted after
    return jsonify(result)
