"""The JSON API under /api/, used by the pages and by scripts (see static/openapi.json).

Every route here is behind the login gate in app.py (session cookie + CSRF,
or an API token), except /api/health and /api/openapi.json.
Errors are JSON: {"error": "...", "where": "..."} with 400 (bad setting),
404 (no such job/file), 409 (the bench is busy), 413 (upload too big),
501 (the bench service lacks the feature).
"""

from __future__ import annotations

import json
import re
import secrets
import shutil
import stat
import tempfile
import time
import zipfile
import zlib
from pathlib import Path, PurePosixPath

from flask import Blueprint, Request, Response, current_app, g, jsonify, request, send_file, session

from ..daemon.importing import read_image_header
from ..errors import DeviceError, InkSliceError, ScanError, SettingError
from . import auth
from .adapter import ACTIVE, NotOffered

bp = Blueprint("api", __name__)

# Job ids and file names are single path components of safe characters: no
# slashes, no leading dot, no "..". The service checks again (job_file only
# returns files inside the job's folder); this is the first of two locks.
JOB_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,79}$")
FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
MAX_ZIP_MEMBERS = 20000


def ext():
    return current_app.extensions["inkslice"]


def svc():
    return ext()["service"]


def err(message, code, where=None):
    body = {"error": message}
    if where:
        body["where"] = where
    return jsonify(body), code


def _check_job_id(job_id):
    if not JOB_ID.match(job_id or ""):
        raise _Refused("bad job id", 400)


def _check_name(name):
    if not FILE_NAME.match(name or "") or ".." in name:
        raise _Refused("bad file name", 400)


class _Refused(Exception):
    def __init__(self, message, code):
        super().__init__(message)
        self.message, self.code = message, code


@bp.errorhandler(_Refused)
def _refused(e):
    return err(e.message, e.code)


@bp.errorhandler(NotOffered)
def _not_offered(e):
    return err(e.problem, 501, e.where)


@bp.errorhandler(SettingError)
def _setting(e):
    return err(e.problem, 400, e.where)


@bp.errorhandler(ScanError)
def _scan(e):
    # an uploaded scan folder the service refused (bad scan.json, a frame of the wrong size ...)
    return err(e.problem, 400, e.where)


@bp.errorhandler(DeviceError)
def _device(e):
    return err(e.problem, 409, e.where)


@bp.errorhandler(InkSliceError)
def _inkslice(e):
    # The facade raises InkSliceError for an unknown job or output name.
    return err(e.problem, 404, e.where)


@bp.errorhandler(KeyError)
def _missing(e):
    return err(f"not found: {e}", 404)


def _json_body():
    data = request.get_json(silent=True)
    if data is None:
        if request.content_length:
            raise _Refused("body must be JSON", 400)
        data = {}
    if not isinstance(data, dict):
        raise _Refused("body must be a JSON object", 400)
    return data


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
    params = _json_body()
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
    _check_job_id(job_id)
    if svc().state().get("state") in ACTIVE:
        return err("a scan is running; stop it first", 409, "scan")
    return jsonify(job_id=svc().resume(job_id)), 201


@bp.get("/jobs")
def jobs():
    sizes = svc().job_sizes()
    return jsonify(jobs=[{**j, "size_bytes": sizes.get(j["id"])} for j in svc().jobs()])


# -- the machine panel: refused (409) while a scan, calibration or commissioning holds the bench --


@bp.post("/machine/preview")
def machine_preview():
    return jsonify(svc().preview())


@bp.post("/machine/home")
def machine_home():
    return jsonify(svc().home_stage())


@bp.post("/machine/jog")
def machine_jog():
    return jsonify(svc().jog(_json_body().get("mm")))


@bp.post("/machine/goto")
def machine_goto():
    return jsonify(svc().goto_level(_json_body().get("level_mm")))


# -- the job manager --------------------------------------------------------------------------


@bp.patch("/jobs/<job_id>")
def rename_job(job_id):
    _check_job_id(job_id)
    return jsonify(svc().rename_job(job_id, _json_body().get("name", "")))


@bp.delete("/jobs/<job_id>")
def delete_job(job_id):
    _check_job_id(job_id)
    svc().delete_job(job_id)
    return jsonify(ok=True)


@bp.post("/jobs/<job_id>/reprocess")
def reprocess_job(job_id):
    _check_job_id(job_id)
    if svc().state().get("state") in ACTIVE:
        return err("a scan is running; stop it first", 409, "scan")
    changes = _json_body().get("settings") or {}
    if not isinstance(changes, dict):
        raise _Refused("settings must be a JSON object", 400)
    return jsonify(job_id=svc().reprocess(job_id, changes)), 202


@bp.post("/jobs/<job_id>/post")
def repost_job(job_id):
    """A new program from the job's height map for another cutter, material, scallop or dialect
    (daemon/repost.py): {dialect, cutter, material, scallop_mm, steep, operations} -> {files}."""
    _check_job_id(job_id)
    options = _json_body()
    if not isinstance(options, dict):
        raise _Refused("the options must be a JSON object", 400)
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
    _check_job_id(job_id)
    return jsonify(svc().job(job_id))


def _job_path(job_id, name) -> Path:
    _check_job_id(job_id)
    _check_name(name)
    if name not in svc().job(job_id).get("outputs", []):
        raise _Refused(f"job {job_id} has no output {name!r}", 404)
    path = svc().job_file(job_id, name)
    if not path.is_file():
        raise _Refused(f"job {job_id} has no output {name!r}", 404)
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
    _check_job_id(job_id)
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


# -- settings -------------------------------------------------------------------------------


@bp.get("/settings")
def get_settings():
    return jsonify(svc().settings())


@bp.route("/settings", methods=["PATCH", "POST"])
def patch_settings():
    return jsonify(svc().update_settings(_json_body()))


# -- calibration -------------------------------------------------------------------------------


@bp.get("/calibration")
def calibration():
    return jsonify(svc().calibration())


@bp.post("/calibration/<step>")
def calibrate(step):
    if not re.match(r"^[a-z_]{1,30}$", step):
        raise _Refused("bad step name", 400)
    return jsonify(svc().calibrate(step))


# -- commissioning (daemon/commissioning.py; shapes in docs/api/README.md) ---------------------------


@bp.get("/commissioning")
def commissioning():
    return jsonify(svc().commissioning())


@bp.get("/commissioning/export")
def commissioning_export():
    doc = svc().export_commissioning()
    body = json.dumps(doc, indent=2) + "\n"
    stamp = time.strftime("%Y%m%d", time.gmtime())
    return Response(
        body,
        mimetype="application/json",
        headers={"Content-Disposition": f'attachment; filename="inkslice-commissioning-{stamp}.json"'},
    )


@bp.post("/commissioning/import")
def commissioning_import():
    return jsonify(svc().import_commissioning(_json_body()))


@bp.post("/commissioning/ink-changed")
def commissioning_ink_changed():
    return jsonify(svc().ink_changed())


@bp.post("/commissioning/<step>/<action>")
def commission(step, action):
    if not re.match(r"^[a-z_]{1,30}$", step) or not re.match(r"^[a-z_]{1,30}$", action):
        raise _Refused("bad step or action name", 400)
    return jsonify(svc().commission(step, action, _json_body()))


# -- USB stick -----------------------------------------------------------------------------------

# The daemon holds the sticks and does the copy (the web service has no device access).


def _usb_offered() -> bool:
    return bool(ext()["config"].get("usb")) and svc().offers("export_to_usb")


@bp.get("/usb")
def usb_sticks():
    sticks = svc().usb_sticks() if _usb_offered() else []
    return jsonify(available=bool(sticks), sticks=sticks)


@bp.post("/jobs/<job_id>/usb")
def usb_export(job_id):
    body = _json_body()
    name = str(body.get("file") or "toolpath.gcode")
    _job_path(job_id, name)  # a known job and a file name the API serves
    if not _usb_offered():
        raise NotOffered("usb", "USB export is switched off on this box")
    stick = body.get("stick")
    result = svc().export_to_usb(job_id, name, str(stick) if stick else None)  # synced and unmounted after
    return jsonify(result)


# -- uploads ---------------------------------------------------------------------------------------


def incoming_dir(data_dir) -> Path:
    """Where uploads are received and unpacked: on the data disk (not /tmp, which may be RAM)."""
    return Path(data_dir) / "web" / "uploads"


def clean_incoming(data_dir) -> int:
    """Remove what a web killed mid-upload left behind (.incoming-*); returns how many."""
    folder = incoming_dir(data_dir)
    gone = 0
    for p in folder.glob(".incoming-*") if folder.is_dir() else ():
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        gone += 1
    return gone


class UploadRequest(Request):
    """Flask's request, with uploaded files received into an unnamed file on the data disk.

    Werkzeug would spool them to the system's temporary folder. The file has no name
    (unlinked at once), so a web killed mid-upload leaves nothing to clean.
    """

    def _get_file_stream(self, total_content_length, content_type, filename=None, content_length=None):
        folder = incoming_dir(current_app.extensions["inkslice"]["config"]["data_dir"])
        folder.mkdir(parents=True, exist_ok=True)
        return tempfile.TemporaryFile("wb+", dir=folder, prefix=".incoming-")


@bp.post("/uploads/scan")
def upload_scan():
    """A scan folder as a zip (scan.json + frames/...). Validated, unpacked, handed to the daemon.

    Refused, leaving nothing behind: not a zip, a member with an absolute path,
    `..`, a backslash, a symlink or a device file; more than MAX_ZIP_MEMBERS
    members; more than max_unzipped_bytes unpacked or a frame of more than
    max_frame_pixels (both read from the zip's directory and the frames' headers
    before anything is unpacked; the sizes are then enforced while unpacking, since
    zipfile stops a member at its declared size); no scan.json, one too deep to
    parse, or one whose frames are not in the zip. The upload itself is capped by
    MAX_CONTENT_LENGTH (413), and waitress refuses a big body from anyone not logged
    in before reading it (limits.py). Everything is received and unpacked under
    DATA/web/uploads/.incoming-*, removed at the end and at the web's start.
    The service checks the folder again (the daemon: importing.py) and keeps its own
    copy, so the unpacked folder is removed whether the import succeeds or not.
    """
    if not svc().offers("import_scan"):
        raise NotOffered("bench", "this bench service cannot import scans")
    cfg = ext()["config"]
    uploads = incoming_dir(cfg["data_dir"])
    uploads.mkdir(parents=True, exist_ok=True)
    f = request.files.get("file")
    blob = f.stream if f is not None else _body_to_disk(uploads, int(cfg["max_upload_bytes"]))
    staging = uploads / f".incoming-{secrets.token_hex(6)}"
    try:
        folder = _unpack_scan_zip(blob, staging, int(cfg["max_unzipped_bytes"]), int(cfg["max_frame_pixels"]))
        job_id = svc().import_scan(folder)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        blob.close()
    return jsonify(job_id=job_id), 201


def _body_to_disk(folder: Path, cap: int):
    """A raw (not multipart) zip body, copied in chunks to an unnamed file on the data disk."""
    out = tempfile.TemporaryFile("wb+", dir=folder, prefix=".incoming-")
    total = 0
    while True:
        chunk = request.stream.read(1 << 16)
        if not chunk:
            break
        total += len(chunk)
        if total > cap:
            out.close()
            raise _Refused(f"upload larger than {cap} bytes", 413)
        out.write(chunk)
    out.seek(0)
    return out


MAX_SCAN_JSON = 16 * 1024 * 1024


def _unpack_scan_zip(blob, staging: Path, max_bytes: int, max_pixels: int = 16 * 1024 * 1024) -> Path:
    try:
        z = zipfile.ZipFile(blob)
    except (zipfile.BadZipFile, OSError, ValueError):
        raise _Refused("not a zip file", 400) from None
    try:
        with z:
            return _unpack_checked(z, staging, max_bytes, max_pixels)
    except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError) as e:
        # a member whose data disagrees with the directory (CRC, size), or an unknown compression
        raise _Refused(f"the zip is damaged: {e}", 400) from None


def _unpack_checked(z: zipfile.ZipFile, staging: Path, max_bytes: int, max_pixels: int) -> Path:
    infos = z.infolist()
    if len(infos) > MAX_ZIP_MEMBERS:
        raise _Refused(f"more than {MAX_ZIP_MEMBERS} files in the zip", 400)
    names = []
    for info in infos:
        n = info.filename
        p = PurePosixPath(n)
        mode = info.external_attr >> 16
        if not n or n.startswith("/") or "\\" in n or ":" in n or ".." in p.parts:
            raise _Refused(f"unsafe path in zip: {n!r}", 400)
        # type bits are optional in a zip (many tools set only permissions); when present,
        # anything but a plain file or folder (a symlink above all) is refused
        if stat.S_IFMT(mode) not in (0, stat.S_IFREG, stat.S_IFDIR):
            raise _Refused(f"not a plain file in zip: {n!r}", 400)
        if not any(part.startswith((".", "__MACOSX")) for part in p.parts):
            names.append(n)  # Finder's litter (.DS_Store, __MACOSX/) is skipped, not refused
    # scan.json at the top, or in a folder up to two deep (myscan/scan.json, or JOB/scan/scan.json
    # as in this box's own archive.zip); only that folder is unpacked
    found = sorted(
        (n for n in names if PurePosixPath(n).name == "scan.json" and len(PurePosixPath(n).parts) <= 3),
        key=lambda n: len(PurePosixPath(n).parts),
    )
    if not found:
        raise _Refused("no scan.json in the zip", 400)
    if len(found) > 1 and len(PurePosixPath(found[0]).parts) == len(PurePosixPath(found[1]).parts):
        raise _Refused(f"several scan.json in the zip ({found[0]}, {found[1]}): which scan?", 400)
    prefix = found[0][: -len("scan.json")]
    wanted = [
        info
        for info in infos
        if not info.is_dir() and info.filename in names and info.filename.startswith(prefix)
    ]
    # the budget from the zip's own directory, before a byte is unpacked (zipfile then stops every
    # member at the size the directory declares, so a lying header cannot overrun it)
    declared = sum(info.file_size for info in wanted)
    if declared > max_bytes:
        raise _Refused(f"the zip unpacks to {declared} bytes, more than {max_bytes}", 400)
    doc = _read_scan_json(z, z.getinfo(prefix + "scan.json"))
    frames = doc.get("frames") if isinstance(doc, dict) else None
    if not isinstance(frames, list) or not frames:
        raise _Refused("scan.json has no frames", 400)
    for i, fr in enumerate(frames):
        if (
            not isinstance(fr, dict)
            or not isinstance(fr.get("file"), str)
            or prefix + fr["file"] not in names
        ):
            raise _Refused(f"scan.json frames[{i}] names a file that is not in the zip", 400)
    for fr in frames:
        _check_frame_pixels(z, prefix + fr["file"], max_pixels)
    staging.mkdir(parents=True)
    total = 0
    for info in wanted:
        dest = staging / info.filename[len(prefix) :]
        dest.parent.mkdir(parents=True, exist_ok=True)
        with z.open(info) as src, open(dest, "wb") as out:
            while True:
                chunk = src.read(1 << 16)
                if not chunk:
                    break
                total += len(chunk)
                if total > max_bytes:
                    raise _Refused(f"the zip unpacks to more than {max_bytes} bytes", 400)
                out.write(chunk)
    return staging


def _read_scan_json(z, info):
    if info.file_size > MAX_SCAN_JSON:
        raise _Refused(f"scan.json is larger than {MAX_SCAN_JSON} bytes", 400)
    try:
        return json.loads(z.read(info))
    except RecursionError:
        raise _Refused("scan.json is nested too deep", 400) from None
    except (ValueError, UnicodeDecodeError):
        raise _Refused("scan.json is not valid JSON", 400) from None


def _check_frame_pixels(z, name, max_pixels):
    """A frame's size from its header (its first bytes, not the whole image)."""
    try:
        with z.open(name) as f:
            w, h, _bits = read_image_header(f, name)
    except ScanError:
        raise _Refused(f"{name} is not a PNG or JPEG image", 400) from None
    if w * h > max_pixels:
        raise _Refused(f"{name} is {w} x {h} pixels, more than {max_pixels}", 400)


# -- the admin's own account -------------------------------------------------------------------------


@bp.post("/password")
def change_password():
    if g.auth != "session":
        return err("change the password from a logged-in browser session", 403)
    body = _json_body()
    creds = ext()["creds"]
    ok, wait = auth.checked_password(
        ext()["limiter"], creds, "password:" + auth.client_address(), body.get("current", "")
    )
    if ok is None:
        resp = jsonify(error=f"too many wrong passwords; try again in {int(wait) + 1} s", where="current")
        return resp, 429, {"Retry-After": str(int(wait) + 1)}
    if not ok:
        return err("the current password is wrong", 403, "current")
    try:
        gen = creds.set_password(body.get("new", ""))
    except ValueError as e:
        return err(str(e), 400, "new")
    session["gen"] = gen  # this session stays in; every other one is logged out
    ext()["sessions"].revoke_all(keep=session.get("sid"))
    auth.first_login_done(ext()["config"])
    return jsonify(ok=True)


@bp.get("/tokens")
def list_tokens():
    return jsonify(tokens=ext()["creds"].list_tokens())


@bp.post("/tokens")
def create_token():
    if g.auth != "session":
        return err("tokens are made from a logged-in browser session", 403)
    rec, token = ext()["creds"].create_token(_json_body().get("name", ""))
    return jsonify(token=token, **rec), 201


@bp.delete("/tokens/<token_id>")
def revoke_token(token_id):
    if not re.match(r"^[0-9a-f]{8}$", token_id):
        raise _Refused("bad token id", 400)
    if not ext()["creds"].revoke_token(token_id):
        return err("no such token", 404)
    return jsonify(ok=True)
