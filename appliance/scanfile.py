"""Reading and writing scan folders (docs/scan-format.md).

A scan is a folder with scan.json and frames/NNNN.png. This module is the only
place that knows the file layout; everything downstream gets a `Scan` whose
camera model is numpy arrays and whose frames load on demand.

Unknown keys in scan.json are kept (in `Scan.extra` and per frame in
`FrameRef.extra`) and written back unchanged.

Everything is checked here, before any computation, for type, finiteness,
range and consistency, so that a hostile or broken scan.json is one clear
ScanError and never a traceback, a gigabyte allocation or a wrong part:
the camera must be a camera (vision/camera_block.py checks its block and
vision/camera.py is the model), the levels must be where the stage can put the liquid (at or above
the base top, below the level with the stage at home, each once), and the
calibration blocks processing reads must have the types it expects.
`check_frames` then checks the frames' files without decoding them.
"""

from __future__ import annotations

import json
import os
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import atomicio
from .errors import ScanError
from .jsoncheck import number, optional_positive, positive_up_to, short
from .vision.camera import CameraModel
from .vision.camera_block import read_camera

FORMAT = "inkslice.scan/1"

# Limits of a scan that a bench box can produce. Beyond them the input is broken
# or hostile, and refusing it early is what keeps processing from a traceback,
# an out-of-memory kill or a part milled from nonsense.
MAX_SCAN_JSON_BYTES = 16 * 1024**2
MAX_DEPTH = 32  # nesting of objects and lists in scan.json
MAX_FRAMES = 10000
MAX_LEVEL_MM = 1000.0  # no bench box moves its liquid a metre
MAX_TANK_AREA_MM2 = 1e7  # 10 m²
LEVEL_EPS_MM = 1e-6  # two levels closer than this are one level
PNG_SIG = b"\x89PNG\r\n\x1a\n"
JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


@dataclass
class FrameRef:
    file: str  # relative to the scan folder
    level_mm: float
    extra: dict = field(default_factory=dict)

    def to_json(self):
        out = dict(self.extra)
        out.update(file=self.file, level_mm=float(self.level_mm))
        return out


@dataclass
class Scan:
    folder: Path
    camera: CameraModel
    frames: list[FrameRef]
    extra: dict = field(default_factory=dict)

    def to_json(self):
        out = dict(self.extra)
        out.update(
            format=FORMAT, units="mm", camera=self.camera.to_json(), frames=[f.to_json() for f in self.frames]
        )
        return out

    @property
    def tank_area_mm2(self) -> float | None:
        """The tank's inner area, for the ink a part displaces (None: not commissioned)."""
        return (self.extra.get("tank") or {}).get("inner_area_mm2")

    @property
    def ink_falls(self) -> bool:
        """The ink falls away from a camera fixed to the tank as the part comes out (no
        overflow holds its level)."""
        return bool((self.extra.get("tank") or {}).get("surface_falls", False))

    def frame_path(self, ref: FrameRef) -> Path:
        return self.folder / ref.file


# -- validation helpers: each names the file and the key that is wrong --------


def _depth_over(doc, limit) -> bool:
    """Whether objects and lists nest deeper than `limit` (iterative: no recursion to exhaust)."""
    stack = [(doc, 1)]
    while stack:
        obj, d = stack.pop()
        if d > limit:
            return True
        children = obj.values() if isinstance(obj, dict) else obj
        stack.extend((c, d + 1) for c in children if isinstance(c, (dict, list)))
    return False


def _optional_number(where, obj, key, label):
    if isinstance(obj, dict) and obj.get(key) is not None:
        return number(where, obj[key], f"{label}.{key}")
    return None


def _object(where, value, label):
    if value is not None and not isinstance(value, dict):
        raise ScanError(where, f"{label} must be an object, got {type(value).__name__} {short(value)}")
    return value or {}


def _check_extras(where, doc):
    """The blocks processing and its report read: their types and physical ranges."""
    top = optional_positive(
        where,
        doc,
        "level_at_home_mm",
        "level_at_home_mm",
        MAX_LEVEL_MM,
        f"the liquid with the stage at home must be above the base top, at most {MAX_LEVEL_MM:g} mm",
        default=MAX_LEVEL_MM,
    )
    if "tank" in doc and doc["tank"] is not None:
        tank = doc["tank"]
        if not isinstance(tank, dict):
            raise ScanError(
                where,
                f'tank must be an object like {{"inner_area_mm2": 31400}}, got '
                f"{type(tank).__name__} {short(tank)}",
            )
        if tank.get("inner_area_mm2") is None:
            raise ScanError(where, "tank.inner_area_mm2 is missing")
        positive_up_to(
            where,
            tank["inner_area_mm2"],
            "tank.inner_area_mm2",
            MAX_TANK_AREA_MM2,
            f"a tank's inner area must be > 0 and at most {MAX_TANK_AREA_MM2:g} mm²",
        )
        if not isinstance(tank.get("surface_falls", False), bool):
            raise ScanError(
                where, f"tank.surface_falls must be true or false, got {short(tank['surface_falls'])}"
            )
    if doc.get("meniscus"):
        men = _object(where, doc["meniscus"], "meniscus")
        for key in ("capillary_length_mm", "contact_angle_deg"):
            if key not in men:
                raise ScanError(where, f"meniscus.{key} is missing")
            number(where, men[key], f"meniscus.{key}")
    cal = _object(where, doc.get("calibration"), "calibration")
    _optional_number(where, cal, "ink_changed", "calibration")
    for what, entry in cal.items():
        if what == "ink_changed":
            continue
        entry = _object(where, entry, f"calibration.{what}")
        for key in ("date", "level_at_home_mm", "area_mm2"):
            _optional_number(where, entry, key, f"calibration.{what}")
        ref = _object(where, entry.get("reference"), f"calibration.{what}.reference")
        for key in ("mean_abs_error_mm", "diameter_mm"):
            _optional_number(where, ref, key, f"calibration.{what}.reference")
    return top


def _frame(where, i, fr, top):
    if not isinstance(fr, dict) or "file" not in fr or "level_mm" not in fr:
        raise ScanError(where, f"frames[{i}] needs 'file' and 'level_mm'")
    rel = fr["file"]
    if not isinstance(rel, str) or not rel.strip():
        raise ScanError(where, f"frames[{i}].file must be a file name, got {short(rel)}")
    if Path(rel).is_absolute() or ".." in Path(rel).parts:
        raise ScanError(where, f"frames[{i}].file must be a path inside the scan folder: {rel!r}")
    level = number(where, fr["level_mm"], f"frames[{i}].level_mm")
    if level < 0:
        raise ScanError(
            where,
            f"frames[{i}].level_mm is {level:g} mm: below the base top (0 mm), which "
            "the liquid never is while the part stands on it",
        )
    if level > top + LEVEL_EPS_MM:
        raise ScanError(
            where,
            f"frames[{i}].level_mm is {level:g} mm: beyond the stage's travel (the liquid "
            f"is at most {top:g} mm above the base top)",
        )
    for key in ("target_mm", "step_mm", "change"):  # the daemon's resume reads these
        if fr.get(key) is not None:
            number(where, fr[key], f"frames[{i}].{key}")
    return FrameRef(rel, level, {k: v for k, v in fr.items() if k not in ("file", "level_mm")})


def _check_levels(where, frames):
    order = sorted(range(len(frames)), key=lambda i: frames[i].level_mm)
    for a, b in zip(order, order[1:]):
        if frames[b].level_mm - frames[a].level_mm < LEVEL_EPS_MM:
            i, j = sorted((a, b))
            raise ScanError(
                where,
                f"frames[{i}] and frames[{j}] are both at level {frames[a].level_mm:g} mm: "
                "each level is scanned once (which frame is right?)",
            )
    files = {}
    for i, fr in enumerate(frames):
        if fr.file in files:
            raise ScanError(
                where, f"frames[{i}] lists {fr.file} a second time (first in frames[{files[fr.file]}])"
            )
        files[fr.file] = i


def load_scan(folder) -> Scan:
    """Read and validate scan.json. Frames are not loaded here (see check_frames, read_frame)."""
    folder = Path(folder)
    where = folder / "scan.json"
    if not folder.is_dir():
        raise ScanError(folder, "scan folder does not exist")
    if not where.is_file():
        raise ScanError(where, "missing (a scan folder needs scan.json)")
    if not _inside(folder, where):
        raise ScanError(where, "is a link to a file outside the scan folder")
    check_scan_json_size(where, where.stat().st_size)
    return scan_from_json(folder, where.read_bytes(), where)


def check_scan_json_size(where, size: int):
    """Refuse a scan.json too big to be one before it is read (the web asks with a zip member's size)."""
    if size > MAX_SCAN_JSON_BYTES:
        raise ScanError(where, f"is {size} bytes; a scan.json is at most {MAX_SCAN_JSON_BYTES} bytes")


def scan_from_json(folder, raw: bytes, where) -> Scan:
    """A Scan of `folder` from scan.json's bytes, with every check load_scan makes (the web checks
    an uploaded zip's scan.json with it before unpacking anything). `where` names it in errors."""
    check_scan_json_size(where, len(raw))
    try:
        doc = json.loads(raw.decode("utf-8"))
    except RecursionError:
        raise ScanError(where, f"nests objects or lists deeper than {MAX_DEPTH} levels") from None
    except (UnicodeDecodeError, ValueError) as e:  # ValueError: JSON errors, a number of 5000 digits
        raise ScanError(where, f"not valid JSON ({short(str(e), 120)})") from None
    if _depth_over(doc, MAX_DEPTH):
        raise ScanError(where, f"nests objects or lists deeper than {MAX_DEPTH} levels")
    if not isinstance(doc, dict):
        raise ScanError(where, "top level must be an object")
    fmt = doc.get("format")
    if fmt is not None and not str(fmt).startswith("inkslice.scan/"):
        raise ScanError(where, f"unknown format {short(fmt)}")
    if doc.get("units", "mm") != "mm":
        raise ScanError(where, f"units must be 'mm', got {short(doc.get('units'))}")
    if "camera" not in doc:
        raise ScanError(where, "'camera' is missing")
    camera = read_camera(where, doc["camera"])
    top = _check_extras(where, doc)
    frames_doc = doc.get("frames")
    if not isinstance(frames_doc, list) or not frames_doc:
        raise ScanError(where, "'frames' must be a non-empty list")
    if len(frames_doc) > MAX_FRAMES:
        raise ScanError(where, f"{len(frames_doc)} frames; a scan has at most {MAX_FRAMES}")
    frames = [_frame(where, i, fr, top) for i, fr in enumerate(frames_doc)]
    _check_levels(where, frames)
    extra = {k: v for k, v in doc.items() if k not in ("format", "units", "camera", "frames")}
    return Scan(Path(folder), camera, frames, extra)


def _inside(folder: Path, path: Path) -> bool:
    """Whether `path`, links followed, is inside `folder`."""
    root = folder.resolve()
    return root in path.resolve().parents


def image_header(path) -> tuple[int, int, int]:
    """(width, height, bits per sample) from a PNG's IHDR or a JPEG's SOF marker, without decoding."""
    with open(path, "rb") as f:
        return read_image_header(f, path)


def read_image_header(f, where) -> tuple[int, int, int]:
    """image_header() of an open binary file (the web reads a zip member's first bytes with it)."""
    head = f.read(33)
    if head[:8] == PNG_SIG and head[12:16] == b"IHDR":
        return struct.unpack(">IIB", head[16:25])
    if head[:2] == b"\xff\xd8":
        f.seek(2)
        while True:
            marker = f.read(2)
            if len(marker) < 2 or marker[0] != 0xFF:
                break
            if marker[1] in (0xD8, 0x01) or 0xD0 <= marker[1] <= 0xD7:
                continue
            seg = f.read(2)
            if len(seg) < 2:
                break
            length = struct.unpack(">H", seg)[0]
            if marker[1] in JPEG_SOF:
                bits, h, w = struct.unpack(">BHH", f.read(5))
                return w, h, bits
            f.seek(length - 2, os.SEEK_CUR)
    raise ScanError(where, "not a PNG or JPEG image (or its header is cut off)")


def check_frames(scan: Scan):
    """Every listed frame is a plain file inside the scan folder, of the camera's size and
    8 bits deep, read from its header: before processing spends minutes on the others."""
    for i, ref in enumerate(scan.frames):
        path = scan.frame_path(ref)
        try:
            st = os.stat(path)
        except OSError:
            raise ScanError(path, f"frame file is missing (frames[{i}] in scan.json)") from None
        if not _inside(scan.folder, path):
            raise ScanError(path, "is a link to a file outside the scan folder; frames must be inside it")
        if not stat.S_ISREG(st.st_mode):
            raise ScanError(path, "is not a plain file")
        check_frame_header(path, image_header(path), scan.camera)


def check_frame_header(where, header: tuple[int, int, int], camera: CameraModel):
    """A frame's (width, height, bits) from its header, against the camera scan.json describes."""
    w, h, bits = header
    if (w, h) != (camera.width, camera.height):
        raise ScanError(where, f"frame is {w}x{h}, scan.json says {camera.width}x{camera.height}")
    if bits != 8:
        raise ScanError(where, f"frame must be 8-bit, it has {bits} bits per sample")


def read_frame(scan: Scan, ref: FrameRef) -> np.ndarray:
    """Load one frame as 8-bit BGR or gray, checked against the camera size."""
    path = scan.frame_path(ref)
    if not path.is_file():
        raise ScanError(path, "frame file is missing")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ScanError(path, "frame does not load as an image (corrupt or truncated?)")
    if img.dtype != np.uint8:
        raise ScanError(path, f"frame must be 8-bit, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.shape[:2] != (scan.camera.height, scan.camera.width):
        raise ScanError(
            path,
            f"frame is {img.shape[1]}x{img.shape[0]}, scan.json says "
            f"{scan.camera.width}x{scan.camera.height}",
        )
    return img


def write_scan_json(scan: Scan):
    atomicio.write_json(scan.folder / "scan.json", scan.to_json())


def write_frame(folder, rel: str, image: np.ndarray):
    """Write a frame PNG atomically (fast compression: frames are big)."""
    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise ScanError(Path(folder) / rel, "could not encode frame as PNG")
    atomicio.write_bytes(Path(folder) / rel, buf.tobytes())
