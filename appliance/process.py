"""`inkslice process SCAN -o OUT`: a scan folder in, a job's outputs out.

The dissertation's system end to end (pipeline "seed"): every frame through
the Canny pipeline (vision/seed.py), the edge points as (x, y, level) slice
points, the 50 x 50 grid over the part, every surface method of the
dissertation (surface/seed.py), the statistics against ground truth when the
scan has one (surface/stats.py), error pictures, heightmap.csv for the chosen
method and a G-code program in the dissertation's format.

Everything is computed before the first byte is written, and every file is
written atomically: a bad scan leaves OUT exactly as it was.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import atomicio, outputs, plots
from .cam.dissertation import dissertation_gcode
from .errors import ScanError, SettingError
from .scanfile import load_scan, read_frame
from .sim import surfaces
from .surface import seed as seed_methods
from .surface.heightmap import HeightMap
from .surface.seedtables import TABLES
from .surface.stats import seed_statistics
from .vision import seed as seed_vision

PIPELINES = ("seed",)


@dataclass
class Job:
    """What one processing run produced, before anything is written."""
    scan_folder: Path
    method: str
    heightmaps: dict                       # method -> HeightMap
    stats: dict = field(default_factory=dict)   # method -> statistics (when truth is known)
    truth: str | None = None
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


def find_truth(scan_folder: Path, truth=None):
    """Ground truth for a rendered scan: `<scan>.truth.json` beside the folder, or a surface name."""
    if truth is False:
        return None
    if isinstance(truth, str) and truth in surfaces.SURFACES:
        return surfaces.get(truth)
    path = Path(truth) if truth else scan_folder.parent / f"{scan_folder.name}.truth.json"
    if not path.is_file():
        if truth:
            raise ScanError(path, "ground-truth file does not exist")
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        name = doc["surface"]
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError) as e:
        raise ScanError(path, f"not a ground-truth file ({e})") from None
    if name not in surfaces.SURFACES:
        raise ScanError(path, f"unknown surface {name!r}")
    return surfaces.get(name)


def _seed_slices(scan):
    slices = []
    for ref in sorted(scan.frames, key=lambda f: -f.level_mm):
        frame = read_frame(scan, ref)
        slices.append(seed_vision.seed_slice(frame, ref.level_mm, scan.camera))
    return slices


def _part_outline_mm(lowest, camera):
    """The part's outline in the most exposed frame: its largest bright blob.

    The grid goes "over the part" (the dissertation drew it by hand); the
    bounding box of all edge points would be stretched by glare and dust.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(lowest.binary, connectivity=8)
    if n < 2:
        raise ScanError("scan", "the part is not visible in the lowest frame")
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    contours, _ = cv2.findContours((labels == biggest).astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    outline = np.vstack([c.reshape(-1, 2) for c in contours]).astype(float)
    return seed_vision.pixels_to_mm(outline, camera)


def run_seed(scan, grid_n=50):
    """All dissertation methods on one scan -> {method: HeightMap}."""
    slices = _seed_slices(scan)
    pts = np.vstack([np.column_stack([s.edges_mm, np.full(len(s.edges_mm), s.level_mm)])
                     for s in slices])
    if len(pts) < 3:
        raise ScanError(scan.folder, "no waterline found in any frame (is the part in view?)")
    x, y = seed_methods.seed_grid(_part_outline_mm(slices[-1], scan.camera), grid_n)
    X, Y = np.meshgrid(x, y)
    grid_px = seed_vision.mm_to_pixels(np.column_stack([X.ravel(), Y.ravel()]), scan.camera)
    exposed = np.stack([seed_vision.exposed_at(s.binary, grid_px).reshape(X.shape) for s in slices])
    levels = [s.level_mm for s in slices]
    return {m: seed_methods.run_method(m, x, y, pts, levels, exposed) for m in seed_methods.METHODS}


def statistics_against(surface, hm: HeightMap) -> dict:
    X, Y = hm.grid()
    on = surface.inside(X, Y)
    z_true = np.where(on, surface.to_dissertation(surface.height(X, Y)), np.nan)
    z_rec = surface.to_dissertation(hm.z)
    norm = surface.table_normaliser or float(np.nanmax(np.abs(z_true)))
    return seed_statistics(z_true, z_rec, norm)


def process(scan_folder, method="lsq3", pipeline="seed", grid_n=50, truth=None) -> Job:
    scan_folder = Path(scan_folder)
    if pipeline not in PIPELINES:
        raise SettingError("pipeline", f"unknown pipeline {pipeline!r}; known: {', '.join(PIPELINES)}")
    if method not in seed_methods.METHODS:
        raise SettingError("method", f"unknown method {method!r}; known: {', '.join(seed_methods.METHODS)}")
    if not (isinstance(grid_n, int) and 3 <= grid_n <= 2000):
        raise SettingError("grid", f"grid must be 3..2000 cells a side, got {grid_n!r}")
    scan = load_scan(scan_folder)
    surface = find_truth(scan_folder, truth)
    t0 = time.perf_counter()
    heightmaps = run_seed(scan, grid_n)
    job = Job(scan_folder, method, heightmaps, truth=surface.name if surface else None)
    job.timings["surface_s"] = time.perf_counter() - t0
    if surface is not None:
        job.stats = {m: statistics_against(surface, hm) for m, hm in heightmaps.items()}
    return job


# -- writing ----------------------------------------------------------------


def report_markdown(job: Job) -> str:
    lines = [f"# InkSlice report: {job.scan_folder.name}", "",
             f"Pipeline: dissertation (Canny edge pixels, 50 x 50 grid). Chosen method: {job.method}.", ""]
    if not job.stats:
        lines.append("No ground truth for this scan: statistics need a rendered scan or a known part.")
        return "\n".join(lines) + "\n"
    lines += [f"Ground truth: `{job.truth}`. Heights in the dissertation's frame; "
              "Ep (table) = 100 Ea / max|Zf|, degree of matching = 100 - Ep (table).", "",
              "| method | max error mm | Ea mm | sigma mm | Ep table % | Ep printed % | matching % |",
              "|---|---|---|---|---|---|---|"]
    for m, s in job.stats.items():
        lines.append(f"| {seed_methods.LABELS[m]} | {s['max_error']:.4f} | {s['Ea']:.4f} | {s['sigma']:.4f} "
                     f"| {s['Ep_table']:.4f} | {s['Ep_printed']:.4f} | {s['matching']:.4f} |")
    if job.truth in TABLES:
        lines += ["", f"The dissertation's table for {job.truth} (Ea / sigma / Ep):", ""]
        for k, (ea, sd, ep) in TABLES[job.truth].items():
            lines.append(f"- {k}: {ea:.4f} / {sd:.4g} / {ep:.4f}")
    lines += ["", "Error pictures: " + ", ".join(f"`error_{m}.png`" for m in job.stats)]
    return "\n".join(lines) + "\n"


def write_outputs(job: Job, out_folder) -> list[str]:
    """Render every output in memory, then write each file atomically."""
    out = Path(out_folder)
    hm = job.heightmaps[job.method]
    files = {
        "heightmap.csv": outputs.heightmap_csv_text(hm).encode(),
        "toolpath.gcode": dissertation_gcode(hm).encode(),
        "report.md": report_markdown(job).encode(),
        "report.json": (json.dumps({"scan": str(job.scan_folder), "pipeline": "seed", "method": job.method,
                                    "truth": job.truth, "statistics": job.stats, "timings": job.timings},
                                   indent=2) + "\n").encode(),
    }
    if job.truth:
        surface = surfaces.get(job.truth)
        vmax = max(float(np.nanmax(np.abs(h.z - surface.height(*h.grid())))) for h in job.heightmaps.values())
        for m, h in job.heightmaps.items():
            X, Y = h.grid()
            err = np.where(surface.inside(X, Y), np.abs(h.z - surface.height(X, Y)), np.nan)
            files[f"error_{m}.png"] = plots.error_map(
                err, h.x, h.y, f"{job.truth}: {seed_methods.LABELS[m]}", vmax=vmax)
    out.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        atomicio.write_bytes(out / name, data)
    return sorted(files)


def process_scan(scan_folder, out_folder, **options) -> dict:
    job = process(scan_folder, **options)
    written = write_outputs(job, out_folder)
    return {"outputs": written, "statistics": job.stats, "method": job.method, "truth": job.truth,
            "out": str(out_folder)}
