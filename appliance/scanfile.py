"""Reading and writing scan folders (shared/docs/scan-format.md).

A scan is a folder with scan.json and frames/NNNN.png. This module is the only
place that knows the file layout; everything downstream gets a `Scan` whose
camera model is numpy arrays and whose frames load on demand.

Unknown keys in scan.json are kept (in `Scan.extra` and per frame in
`FrameRef.extra`) and written back unchanged.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import atomicio
from .errors import ScanError

FORMAT = "inkslice.scan/1"


@dataclass
class CameraModel:
    width: int
    height: int
    homography: np.ndarray            # undistorted pixel (u, v, 1) -> liquid plane (x, y, 1), mm
    K: np.ndarray | None = None       # OpenCV camera matrix
    dist: np.ndarray | None = None    # OpenCV distortion coefficients
    height_mm: float | None = None    # camera centre above the liquid plane
    extra: dict = field(default_factory=dict)

    def to_json(self):
        out = dict(self.extra)
        out.update(width=self.width, height=self.height,
                   homography=np.asarray(self.homography, float).tolist())
        if self.K is not None:
            out["K"] = np.asarray(self.K, float).tolist()
        if self.dist is not None:
            out["dist"] = np.asarray(self.dist, float).ravel().tolist()
        if self.height_mm is not None:
            out["height_mm"] = float(self.height_mm)
        return out


@dataclass
class FrameRef:
    file: str            # relative to the scan folder
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
        out.update(format=FORMAT, units="mm", camera=self.camera.to_json(),
                   frames=[f.to_json() for f in self.frames])
        return out

    def frame_path(self, ref: FrameRef) -> Path:
        return self.folder / ref.file


# -- validation helpers: each names the file and the key that is wrong --------

def _matrix(where, obj, key, shape):
    try:
        m = np.asarray(obj, dtype=float)
    except (TypeError, ValueError):
        raise ScanError(where, f"{key} is not a matrix of numbers") from None
    if m.shape != shape:
        raise ScanError(where, f"{key} must be {shape[0]}x{shape[1]}, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ScanError(where, f"{key} has a non-finite entry")
    return m


def _number(where, value, key):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScanError(where, f"{key} is not a number: {value!r}")
    if not math.isfinite(value):
        raise ScanError(where, f"{key} is not finite: {value!r}")
    return float(value)


def _camera(where, cam):
    if not isinstance(cam, dict):
        raise ScanError(where, "'camera' must be an object")
    known = {"width", "height", "homography", "K", "dist", "height_mm"}
    for key in ("width", "height", "homography"):
        if key not in cam:
            raise ScanError(where, f"camera.{key} is missing")
    w, h = cam["width"], cam["height"]
    if not (isinstance(w, int) and isinstance(h, int) and w > 0 and h > 0):
        raise ScanError(where, f"camera.width/height must be positive integers, got {w!r} x {h!r}")
    H = _matrix(where, cam["homography"], "camera.homography", (3, 3))
    if abs(np.linalg.det(H)) < 1e-12:
        raise ScanError(where, "camera.homography is singular")
    K = _matrix(where, cam["K"], "camera.K", (3, 3)) if cam.get("K") is not None else None
    dist = None
    if cam.get("dist") is not None:
        dist = np.asarray(cam["dist"], dtype=float).ravel()
        if dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
            raise ScanError(where, "camera.dist must be 4, 5, 8, 12 or 14 finite numbers")
    hmm = _number(where, cam["height_mm"], "camera.height_mm") if cam.get("height_mm") is not None else None
    return CameraModel(w, h, H, K, dist, hmm, {k: v for k, v in cam.items() if k not in known})


def load_scan(folder) -> Scan:
    """Read and validate scan.json. Frames are not loaded here (see read_frame)."""
    folder = Path(folder)
    where = folder / "scan.json"
    if not folder.is_dir():
        raise ScanError(folder, "scan folder does not exist")
    if not where.is_file():
        raise ScanError(where, "missing (a scan folder needs scan.json)")
    try:
        doc = json.loads(where.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ScanError(where, f"not valid JSON ({e})") from None
    if not isinstance(doc, dict):
        raise ScanError(where, "top level must be an object")
    fmt = doc.get("format")
    if fmt is not None and not str(fmt).startswith("inkslice.scan/"):
        raise ScanError(where, f"unknown format {fmt!r}")
    if doc.get("units", "mm") != "mm":
        raise ScanError(where, f"units must be 'mm', got {doc.get('units')!r}")
    if "camera" not in doc:
        raise ScanError(where, "'camera' is missing")
    camera = _camera(where, doc["camera"])
    frames_doc = doc.get("frames")
    if not isinstance(frames_doc, list) or not frames_doc:
        raise ScanError(where, "'frames' must be a non-empty list")
    frames = []
    for i, fr in enumerate(frames_doc):
        if not isinstance(fr, dict) or "file" not in fr or "level_mm" not in fr:
            raise ScanError(where, f"frames[{i}] needs 'file' and 'level_mm'")
        level = _number(where, fr["level_mm"], f"frames[{i}].level_mm")
        rel = str(fr["file"])
        if Path(rel).is_absolute() or ".." in Path(rel).parts:
            raise ScanError(where, f"frames[{i}].file must be a path inside the scan folder: {rel!r}")
        frames.append(FrameRef(rel, level, {k: v for k, v in fr.items() if k not in ("file", "level_mm")}))
    extra = {k: v for k, v in doc.items() if k not in ("format", "units", "camera", "frames")}
    return Scan(folder, camera, frames, extra)


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
        raise ScanError(path, f"frame is {img.shape[1]}x{img.shape[0]}, scan.json says "
                              f"{scan.camera.width}x{scan.camera.height}")
    return img


def write_scan_json(scan: Scan):
    atomicio.write_json(scan.folder / "scan.json", scan.to_json())


def write_frame(folder, rel: str, image: np.ndarray):
    """Write a frame PNG atomically (fast compression: frames are big)."""
    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise ScanError(Path(folder) / rel, "could not encode frame as PNG")
    atomicio.write_bytes(Path(folder) / rel, buf.tobytes())
