"""A scan from elsewhere, uploaded as a zip: POST /api/uploads/scan.

The web checks what only it can see, the zip: its members' paths and types, how far it
unpacks, where scan.json sits in it. scan.json itself is checked with the scan format's
own rules (scanfile.scan_from_json, the checks load_scan makes) and every frame's header
against its camera (scanfile.check_frame_header), all from the zip's directory and the
first bytes of each member, before a byte is unpacked. The daemon then checks the unpacked
folder again (daemon/importing.py) and keeps its own copy.

Everything is received and unpacked on the data disk under DATA/web/uploads/.incoming-*
(not /tmp, which may be RAM), removed at the end and at the web's start (clean_incoming).
"""

from __future__ import annotations

import secrets
import shutil
import stat
import tempfile
import zipfile
import zlib
from pathlib import Path, PurePosixPath

from flask import Blueprint, Request, current_app, jsonify, request

from ..scanfile import check_frame_header, check_scan_json_size, read_image_header, scan_from_json
from .apicore import Refused, ext, json_errors, svc

bp = json_errors(Blueprint("uploads", __name__))
MAX_ZIP_MEMBERS = 20000


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
    zipfile stops a member at its declared size); no scan.json, one the scan format
    refuses (scanfile), or one whose frames are not in the zip or not of its camera's
    size. The upload itself is capped by
    MAX_CONTENT_LENGTH (413), and waitress refuses a big body from anyone not logged
    in before reading it (limits.py). Everything is received and unpacked under
    DATA/web/uploads/.incoming-*, removed at the end and at the web's start.
    The service checks the folder again (the daemon: importing.py) and keeps its own
    copy, so the unpacked folder is removed whether the import succeeds or not.
    """
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
            raise Refused(f"upload larger than {cap} bytes", 413)
        out.write(chunk)
    out.seek(0)
    return out


def _unpack_scan_zip(blob, staging: Path, max_bytes: int, max_pixels: int = 16 * 1024 * 1024) -> Path:
    try:
        z = zipfile.ZipFile(blob)
    except (zipfile.BadZipFile, OSError, ValueError):
        raise Refused("not a zip file", 400) from None
    try:
        with z:
            wanted, prefix = _scan_members(z, max_bytes)
            _check_scan(z, prefix, {info.filename for info in wanted}, max_pixels)
            return _unpack(z, wanted, prefix, staging, max_bytes)
    except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError) as e:
        # a member whose data disagrees with the directory (CRC, size), or an unknown compression
        raise Refused(f"the zip is damaged: {e}", 400) from None


def _scan_members(z: zipfile.ZipFile, max_bytes: int) -> tuple[list[zipfile.ZipInfo], str]:
    """The members of the scan's folder (those to unpack) and that folder's path in the zip."""
    infos = z.infolist()
    if len(infos) > MAX_ZIP_MEMBERS:
        raise Refused(f"more than {MAX_ZIP_MEMBERS} files in the zip", 400)
    names = []
    for info in infos:
        n = info.filename
        p = PurePosixPath(n)
        mode = info.external_attr >> 16
        if not n or n.startswith("/") or "\\" in n or ":" in n or ".." in p.parts:
            raise Refused(f"unsafe path in zip: {n!r}", 400)
        # type bits are optional in a zip (many tools set only permissions); when present,
        # anything but a plain file or folder (a symlink above all) is refused
        if stat.S_IFMT(mode) not in (0, stat.S_IFREG, stat.S_IFDIR):
            raise Refused(f"not a plain file in zip: {n!r}", 400)
        if not any(part.startswith((".", "__MACOSX")) for part in p.parts):
            names.append(n)  # Finder's litter (.DS_Store, __MACOSX/) is skipped, not refused
    # scan.json at the top, or in a folder up to two deep (myscan/scan.json, or JOB/scan/scan.json
    # as in this box's own archive.zip); only that folder is unpacked
    found = sorted(
        (n for n in names if PurePosixPath(n).name == "scan.json" and len(PurePosixPath(n).parts) <= 3),
        key=lambda n: len(PurePosixPath(n).parts),
    )
    if not found:
        raise Refused("no scan.json in the zip", 400)
    if len(found) > 1 and len(PurePosixPath(found[0]).parts) == len(PurePosixPath(found[1]).parts):
        raise Refused(f"several scan.json in the zip ({found[0]}, {found[1]}): which scan?", 400)
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
        raise Refused(f"the zip unpacks to {declared} bytes, more than {max_bytes}", 400)
    return wanted, prefix


def _check_scan(z: zipfile.ZipFile, prefix: str, members: set[str], max_pixels: int):
    """scan.json by the scan format's rules, then each frame it lists: in the zip, and its header
    (a few bytes, not the image) within max_pixels and the size of scan.json's camera."""
    info = z.getinfo(prefix + "scan.json")
    check_scan_json_size(info.filename, info.file_size)
    scan = scan_from_json(PurePosixPath(prefix), z.read(info), info.filename)
    for i, ref in enumerate(scan.frames):
        name = prefix + ref.file
        if name not in members:
            raise Refused(f"scan.json frames[{i}] names a file that is not in the zip ({ref.file})", 400)
        with z.open(name) as f:
            header = read_image_header(f, name)
        w, h, _bits = header
        if w * h > max_pixels:
            raise Refused(f"{name} is {w} x {h} pixels, more than {max_pixels}", 400)
        check_frame_header(name, header, scan.camera)


def _unpack(z: zipfile.ZipFile, wanted, prefix: str, staging: Path, max_bytes: int) -> Path:
    """The scan's folder into staging, the byte budget enforced as it is written."""
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
                    raise Refused(f"the zip unpacks to more than {max_bytes} bytes", 400)
                out.write(chunk)
    return staging
