"""The two pipelines, each from a scan's frames to height maps, and what one run produced.

- "inkslice" (the default): every frame through our integer-first vision
  (sub-pixel waterlines in mm, vision/pipeline.py), then surface/reconstruct
  (first exposure, walls kept out, displacement and meniscus corrected, a
  regularised grid fit).
- "seed": the seed method, the 2013 dissertation's system, faithfully (chapter 3-4):
  Canny edge pixels as (x, y, level) points, the 50 x 50 grid over the part,
  its surface methods (surface/seed.py).

Height maps are keyed "pipeline:method"; label() names them for people.
process.py runs these for `inkslice process` and writes the outputs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import outputs, progress
from .errors import ScanError, SettingError
from .scanfile import read_frame
from .surface import seed as seed_methods
from .surface.heightmap import HeightMap
from .vision import seed as seed_vision
from .waterlines import extract_waterlines, frames_top_down

PIPELINES = ("inkslice", "seed")
OUR_METHODS = ("fit",)
LABELS = {"fit": "InkSlice regularised fit", **seed_methods.LABELS}


@dataclass
class Job:
    """What one processing run produced, before anything is written."""

    scan_folder: Path
    pipeline: str
    method: str
    heightmaps: dict  # "pipeline:method" -> HeightMap
    stats: dict = field(default_factory=dict)  # same keys -> statistics (when truth is known)
    truth: str | None = None  # the ground truth's name
    reference: object = None  # the ground truth itself (a known part)
    timings: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    calibration: dict = field(default_factory=dict)  # calibration_used.describe: what was used, warnings

    @property
    def key(self):
        return f"{self.pipeline}:{self.method}"

    @property
    def heightmap(self) -> HeightMap:
        return self.heightmaps[self.key]


def label(key: str) -> str:
    pipeline, method = key.split(":")
    if pipeline == "seed":
        return f"{LABELS[method]} (seed)"
    return LABELS[method] if method == "fit" else f"{LABELS[method]} (our waterlines)"


# -- the seed method ----------------------------------------------------------------


def _part_outline_mm(lowest, camera):
    """The part's outline in the most exposed frame: its largest bright blob.

    The grid goes "over the part" (the dissertation drew it by hand); the
    bounding box of all edge points would be stretched by glare and dust.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(lowest.binary, connectivity=8)
    if n < 2:
        raise ScanError("scan", "the part is not visible in the lowest frame")
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    contours, _ = cv2.findContours(
        (labels == biggest).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE
    )
    outline = np.vstack([c.reshape(-1, 2) for c in contours]).astype(float)
    return camera.pixels_to_mm(outline)


def run_seed(scan, grid_n=50):
    """The seed method with each of its surface methods on one scan -> {"seed:method": HeightMap}."""
    progress.stage("the seed method")
    slices = [
        seed_vision.seed_slice(read_frame(scan, ref), ref.level_mm, scan.camera)
        for ref in frames_top_down(scan)
    ]
    pts = np.vstack([np.column_stack([s.edges_mm, np.full(len(s.edges_mm), s.level_mm)]) for s in slices])
    if len(pts) < 3:
        raise ScanError(scan.folder, "no waterline found in any frame (is the part in view?)")
    x, y = seed_methods.seed_grid(_part_outline_mm(slices[-1], scan.camera), grid_n)
    X, Y = np.meshgrid(x, y)
    grid_px = scan.camera.mm_to_pixels(np.column_stack([X.ravel(), Y.ravel()]))
    exposed = np.stack([seed_vision.exposed_at(s.binary, grid_px).reshape(X.shape) for s in slices])
    levels = [s.level_mm for s in slices]
    return {f"seed:{m}": seed_methods.run_method(m, x, y, pts, levels, exposed) for m in seed_methods.METHODS}


# -- ours ---------------------------------------------------------------------------


def _waterline_bounds(waterlines):
    pts = [wl.points for wl in waterlines if len(wl.points)]
    if not pts:
        raise ScanError("scan", "no waterline found in any frame (is the part in view?)")
    p = np.vstack(pts)
    return (float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()), float(p[:, 1].max()))


def camera_view(camera):
    """The camera's pose for the fit (surface/perspective.py), if the calibration has one."""
    from .surface.perspective import Perspective

    return Perspective.of(camera)


def meniscus_model(scan, meniscus):
    """The meniscus correction: a meniscus.json from `calibrate --reference`, scan.json's, or none."""
    if meniscus is False or (meniscus is None and not scan.extra.get("meniscus")):
        return None
    if meniscus is None:
        return outputs.meniscus_model(scan.extra["meniscus"], scan.camera, scan.folder / "scan.json")
    if not isinstance(meniscus, (str, Path)):
        return meniscus  # a MeniscusModel already
    path = Path(meniscus)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SettingError(path, "meniscus model file does not exist") from None
    except (ValueError, UnicodeDecodeError) as e:
        raise SettingError(path, f"not valid JSON ({e})") from None
    return outputs.meniscus_model(doc, scan.camera, path)


def run_inkslice(
    scan,
    methods,
    grid_n=50,
    spacing_mm=None,
    displacement=True,
    meniscus=None,
    waterlines_of=extract_waterlines,
    pair_memo=None,
):
    """Our pipeline -> ({"inkslice:method": HeightMap}, diagnostics, waterlines). `waterlines_of`:
    scan -> its waterlines, and `pair_memo` the frame pairs' shifts (registration.pair_shifts):
    a processing child that followed the scan has most of both already."""
    from .surface.base import stand_on_base
    from .surface.reconstruct import GridSpec, ReconstructOptions, reconstruct

    waterlines = waterlines_of(scan)
    bounds = _waterline_bounds(waterlines)
    # the grid spans the part's outline once the walls' raised edges are put back
    grid = GridSpec(None, spacing_mm=spacing_mm) if spacing_mm else GridSpec(None, n=grid_n)
    tank = scan.tank_area_mm2 if displacement else None
    falls = scan.ink_falls and tank is not None
    model = meniscus_model(scan, meniscus)
    view = camera_view(scan.camera)
    out, diag = {}, {}
    for m in methods:
        progress.stage(f"surface ({m})")
        rec = reconstruct(
            waterlines,
            grid,
            ReconstructOptions(
                method=m,
                tank_area_mm2=tank,
                ink_falls=falls,
                meniscus=model,
                perspective=view,
                pixel_mm=scan.camera.pixel_mm(),
                pair_memo=pair_memo,
            ),
        )
        bounds = rec.diagnostics.get("bounds", bounds)
        out[f"inkslice:{m}"], fix = stand_on_base(rec.heightmap)
        diag[m] = {
            "smoothing_mm": rec.smoothing,
            **{
                k: v
                for k, v in rec.diagnostics.items()
                if k
                in (
                    "wall_points",
                    "points",
                    "seconds",
                    "notes",
                    "smoothing_mm",
                    "displacement",
                    "silhouette_points",
                    "occluded_nodes",
                    "edge_cells",
                    "held_pools",
                    "held_notes",
                )
            },
        }
        at_base = len(scan.frames) - len(waterlines)
        if at_base:
            diag[m]["notes"] = list(diag[m].get("notes", [])) + [
                f"{at_base} frame(s) at or below level 0 mm not used: the base top is out of the ink "
                "there, and its outline is not the part's waterline"
            ]
        diag[m]["base"] = fix.to_json()
        diag[m]["base_notes"] = fix.sentences()
    diag["grid"] = {"bounds": bounds, "n": grid_n, "spacing_mm": spacing_mm}
    diag["corrections"] = {"displacement_tank_area_mm2": tank, "meniscus": bool(model)}
    return out, diag, waterlines
