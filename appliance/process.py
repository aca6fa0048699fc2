"""`inkslice process SCAN -o OUT`: a scan folder in, a job's outputs out.

Two pipelines share this entry point:

- "inkslice" (the default): every frame through our integer-first vision
  (sub-pixel waterlines in mm, vision/pipeline.py), then surface/reconstruct
  (first exposure, walls kept out, displacement and meniscus corrected, a
  regularised grid fit), then a cutter-compensated finishing program (cam/).
- "seed": the dissertation's system, faithfully (chapter 3-4): Canny edge
  pixels as (x, y, level) points, the 50 x 50 grid over the part, its surface
  methods (surface/seed.py), its G-code format (cam/dissertation.py).

With `compare`, the other pipeline's methods are run on the same frames so
the report can put them side by side. Statistics (eqs 3-27..3-30) are computed
when the caller passes the part's ground truth (`truth`: a known part, with
height(x, y), inside(x, y), to_dissertation(z), table_normaliser and name;
for a rendered scan the command finds it, see sim/truth.py).

The output contract: a run either writes the complete set (height map, STL,
finishing program, report, pictures) or fails naming the reason, and a bad
scan or a part no program can be made for leaves OUT exactly as it was.
Everything is computed before the first byte is written, then the set is
built in a sibling folder and swapped in whole (atomicio.replace_folder): no
file of an earlier run survives beside the new ones. Our height map stands on
the base plane before anything is written (surface/base.py: heights below
the base top clamped, gaps inside the part filled), counted in the report.
"""

from __future__ import annotations

import json
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import atomicio, outputs, plots, progress
from .cam.dissertation import dissertation_gcode
from .errors import InkSliceError, ScanError, SettingError
from .scanfile import check_frames, load_scan, read_frame
from .surface import seed as seed_methods
from .surface.heightmap import HeightMap
from .surface.seedtables import TABLES
from .surface.stats import seed_statistics
from .vision import seed as seed_vision

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
        return f"{LABELS[method]} (dissertation)"
    return LABELS[method] if method == "fit" else f"{LABELS[method]} (our waterlines)"


def _frames_top_down(scan):
    return sorted(scan.frames, key=lambda f: -f.level_mm)


# -- the dissertation's pipeline ---------------------------------------------------


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
    """All dissertation methods on one scan -> {"seed:method": HeightMap}."""
    progress.stage("the dissertation's pipeline")
    slices = [
        seed_vision.seed_slice(read_frame(scan, ref), ref.level_mm, scan.camera)
        for ref in _frames_top_down(scan)
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


CONFIRMING_FRAMES = 2  # lower frames that must agree a pixel is part (vision/pipeline.py)
REREAD_ABOVE = 3  # frames above the first showing the part read again for its top


def extract_waterlines(scan):
    """Every frame's waterline, top level first. Each frame is read with the next lower
    ones beside it (exposure is monotone: what is part here is part below, so what they
    do not show is glare or flotsam); only those few frames are held at a time."""
    from .surface.slices import shows_waterline
    from .vision.pipeline import WaterlineExtractor

    extractor = WaterlineExtractor(scan.camera, no_part="empty")  # a scan starts above the part
    frames = [ref for ref in _frames_top_down(scan) if shows_waterline(ref.level_mm)]
    ahead = deque()
    out = []
    above = deque(maxlen=REREAD_ABOVE)  # the last frames, while none has shown the part
    progress.stage("waterlines", total=len(frames))
    for i in range(len(frames)):
        progress.step(i)
        while len(ahead) < CONFIRMING_FRAMES + 1 and i + len(ahead) < len(frames):
            nxt = frames[i + len(ahead)]
            ahead.append((nxt.level_mm, read_frame(scan, nxt)))
        level, frame = ahead.popleft()
        out.append(extractor.extract(frame, level, below=list(ahead)))
        if above and out[-1].loops:
            # the first frame showing the part: the ones above may show its top as a sliver
            found = extractor.read_above(list(reversed(above)), below=[(level, frame)] + list(ahead))
            for k, wl in enumerate(found):
                out[-2 - k] = wl
        if any(wl.loops for wl in out):
            above.clear()
        else:
            above.append((level, frame))
    return out


def _waterline_bounds(waterlines):
    pts = [wl.points for wl in waterlines if len(wl.points)]
    if not pts:
        raise ScanError("scan", "no waterline found in any frame (is the part in view?)")
    p = np.vstack(pts)
    return (float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()), float(p[:, 1].max()))


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


def run_inkslice(scan, methods, grid_n=50, spacing_mm=None, displacement=True, meniscus=None):
    """Our pipeline -> ({"inkslice:method": HeightMap}, diagnostics, waterlines)."""
    from .surface.base import stand_on_base
    from .surface.reconstruct import GridSpec, ReconstructOptions, reconstruct
    from .surface.slices import Perspective

    waterlines = extract_waterlines(scan)
    bounds = _waterline_bounds(waterlines)
    # the grid spans the part's outline once the walls' raised edges are put back
    grid = GridSpec(None, spacing_mm=spacing_mm) if spacing_mm else GridSpec(None, n=grid_n)
    tank = (scan.extra.get("tank") or {}).get("inner_area_mm2") if displacement else None
    model = meniscus_model(scan, meniscus)
    view = (
        Perspective(scan.camera.centre_xy(), scan.camera.height_mm)
        if scan.camera.height_mm and scan.camera.K is not None
        else None
    )
    out, diag = {}, {}
    for m in methods:
        progress.stage(f"surface ({m})")
        rec = reconstruct(
            waterlines,
            grid,
            ReconstructOptions(
                method=m,
                tank_area_mm2=tank,
                meniscus=model,
                perspective=view,
                pixel_mm=scan.camera.pixel_mm(),
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


# -- statistics ---------------------------------------------------------------------


def statistics_against(surface, hm: HeightMap) -> dict:
    X, Y = hm.grid()
    on = surface.inside(X, Y)
    z_true = np.where(on, surface.to_dissertation(surface.height(X, Y)), np.nan)
    z_rec = surface.to_dissertation(hm.z)
    norm = surface.table_normaliser or float(np.nanmax(np.abs(z_true)))
    return seed_statistics(z_true, z_rec, norm)


def process(
    scan_folder,
    method=None,
    pipeline="inkslice",
    grid_n=50,
    spacing_mm=None,
    truth=None,
    compare=False,
    displacement=True,
    meniscus=None,
) -> Job:
    scan_folder = Path(scan_folder)
    if pipeline not in PIPELINES:
        raise SettingError("pipeline", f"unknown pipeline {pipeline!r}; known: {', '.join(PIPELINES)}")
    method = method or ("fit" if pipeline == "inkslice" else "lsq3")
    allowed = (OUR_METHODS + seed_methods.METHODS) if pipeline == "inkslice" else seed_methods.METHODS
    if method not in allowed:
        raise SettingError(
            "method", f"unknown method {method!r} for the {pipeline} pipeline; known: {', '.join(allowed)}"
        )
    if not (isinstance(grid_n, int) and 3 <= grid_n <= 2000):
        raise SettingError("grid", f"grid must be 3..2000 cells a side, got {grid_n!r}")
    scan = load_scan(scan_folder)
    check_frames(scan)
    surface = truth or None  # False: none (as None)
    job = Job(scan_folder, pipeline, method, {}, truth=surface.name if surface else None, reference=surface)
    from .calibration_used import describe

    ours = pipeline == "inkslice" or compare  # the dissertation's pipeline corrects neither
    if ours:
        meniscus_model(scan, meniscus)  # a bad model fails now, not after the vision
    job.calibration = describe(scan, displacement and ours, meniscus if ours else False)
    if pipeline == "seed" or compare:
        t0 = time.perf_counter()
        job.heightmaps.update(run_seed(scan, grid_n))
        job.timings["seed_s"] = time.perf_counter() - t0
    if pipeline == "inkslice" or compare:
        t0 = time.perf_counter()
        methods = (method,) if not compare else tuple(dict.fromkeys((method, "fit")))
        hms, job.diagnostics, _ = run_inkslice(scan, methods, grid_n, spacing_mm, displacement, meniscus)
        job.heightmaps.update(hms)
        job.notes += [
            f"{label('inkslice:' + m)}: {n}" for m in methods for n in job.diagnostics[m]["base_notes"]
        ]
        job.timings["inkslice_s"] = time.perf_counter() - t0
    if surface is not None:
        for k, hm in job.heightmaps.items():
            try:
                job.stats[k] = statistics_against(surface, hm)
            except ValueError as e:  # e.g. the baseline's grid put over a glare blob, not the part
                job.notes.append(f"{label(k)}: no statistics ({e})")
    return job


# -- writing ------------------------------------------------------------------------


def report_markdown(job: Job) -> str:
    what = (
        "InkSlice (sub-pixel waterlines, regularised fit)"
        if job.pipeline == "inkslice"
        else "the dissertation's (Canny edge pixels, 50 x 50 grid)"
    )
    lines = [
        f"# InkSlice report: {job.scan_folder.name}",
        "",
        f"Pipeline: {what}. Method written to heightmap.csv and the G-code: {label(job.key)}.",
        "",
    ]
    lines += [f"- {n}" for n in job.notes]
    if job.calibration:
        from .calibration_used import markdown

        lines += markdown(job.calibration) + [""]
    base = job.diagnostics.get(job.method, {}).get("base") if job.pipeline == "inkslice" else None
    if base is not None:
        lines += [
            "",
            "Base plane (the part stands on the base top, z = 0): "
            f"{base['clamped_cells']} cells clamped up to it (deepest dip {base['deepest_dip_mm']:.3f} mm), "
            f"{base['filled_cells']} gap cells filled from their neighbours, "
            f"{base['base_cells']} hole cells set to the base top.",
            "",
        ]
    lines += uncertainty_markdown(job)
    if not job.stats:
        lines.append("No ground truth for this scan: statistics need a rendered scan or a known part.")
        return "\n".join(lines) + "\n"
    lines += [
        f"Ground truth: `{job.truth}`. Heights in the dissertation's frame; "
        "Ep (table) = 100 Ea / max|Zf|, degree of matching = 100 - Ep (table).",
        "",
        "| method | max error mm | Ea mm | sigma mm | Ep table % | Ep printed % | matching % |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, s in job.stats.items():
        lines.append(
            f"| {label(k)} | {s['max_error']:.4f} | {s['Ea']:.4f} | {s['sigma']:.4f} "
            f"| {s['Ep_table']:.4f} | {s['Ep_printed']:.4f} | {s['matching']:.4f} |"
        )
    if job.truth in TABLES:
        lines += ["", f"The dissertation's table for {job.truth} (Ea / sigma / Ep):", ""]
        for k, (ea, sd, ep) in TABLES[job.truth].items():
            lines.append(f"- {k}: {ea:.4f} / {sd:.4g} / {ep:.4f}")
    lines += ["", "Error pictures: " + ", ".join(f"`{png_name(k)}`" for k in job.stats)]
    return "\n".join(lines) + "\n"


UNCERTAINTY_PNG = "uncertainty.png"


def uncertainty_summary(job: Job, threshold_mm=None) -> dict | None:
    """Where the written height map is sure and where not: sources, low-confidence regions."""
    from .surface.uncertainty import DEFAULT_UNCERTAIN_MM, low_confidence_regions, source_summary

    hm = job.heightmap
    if hm.sigma is None:
        return None
    t = DEFAULT_UNCERTAIN_MM if threshold_mm is None else threshold_mm
    on = hm.on_part & np.isfinite(hm.sigma)
    regions = low_confidence_regions(hm, t)
    return {
        "threshold_mm": t,
        "sources": source_summary(hm),
        "median_mm": float(np.median(hm.sigma[on])) if on.any() else None,
        "low_confidence_share": float(sum(r.share for r in regions)),
        "regions": [
            {
                "xmin": r.xmin,
                "xmax": r.xmax,
                "ymin": r.ymin,
                "ymax": r.ymax,
                "share": r.share,
                "worst_mm": r.worst_mm,
                "source": r.source,
            }
            for r in regions
        ],
    }


def uncertainty_markdown(job: Job, most=8) -> list[str]:
    u = job.diagnostics.get("uncertainty") or uncertainty_summary(job)
    if u is None:
        return []
    src = ", ".join(f"{name} {100 * share:.1f} %" for name, share in u["sources"].items())
    out = [
        "",
        f"Uncertainty per cell (`{UNCERTAINTY_PNG}`, and the columns source, uncertainty_mm of "
        f"heightmap.csv): median {u['median_mm']:.3f} mm. How the cells were obtained: {src}.",
        "",
    ]
    if not u["regions"]:
        out += [f"Every cell is within {u['threshold_mm']:g} mm.", ""]
        return out
    out += [
        f"Low confidence (uncertainty over {u['threshold_mm']:g} mm): {100 * u['low_confidence_share']:.1f} % "
        f"of the part in {len(u['regions'])} region(s), largest first (the G-code header lists them too):",
        "",
        "| region | x mm | y mm | share % | up to mm | mostly |",
        "|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(u["regions"][:most], start=1):
        out.append(
            f"| {i} | {r['xmin']:.1f} .. {r['xmax']:.1f} | {r['ymin']:.1f} .. {r['ymax']:.1f} "
            f"| {100 * r['share']:.1f} | {r['worst_mm']:.2f} | {r['source']} |"
        )
    if len(u["regions"]) > most:
        out.append(
            f"| ... | {len(u['regions']) - most} smaller regions | | "
            f"{100 * sum(r['share'] for r in u['regions'][most:]):.1f} | | |"
        )
    return out + [""]


def is_output_name(name: str) -> bool:
    """A file name a run of `process` writes (any pipeline, method or dialect)."""
    import fnmatch

    return any(
        fnmatch.fnmatch(name, p)
        for p in (
            "heightmap.csv",
            "surface.stl",
            "toolpath*.gcode",
            "report.md",
            "report.json",
            "error_*.png",
            UNCERTAINTY_PNG,
        )
    )


def png_name(key):
    """error_lsq3.png for the dissertation's methods (its figures 5-1..5-16), error_inkslice_fit.png for ours."""
    pipeline, method = key.split(":")
    return f"error_{method}.png" if pipeline == "seed" else f"error_{pipeline}_{method}.png"


def toolpath_files(job: Job, cam_options=None) -> dict:
    """G-code for the chosen height map: ours, and the dissertation's format beside it."""
    hm = job.heightmap
    files = {"toolpath-dissertation.gcode": dissertation_gcode(hm).encode()}
    if job.pipeline == "seed":
        files["toolpath.gcode"] = files.pop("toolpath-dissertation.gcode")
        return files
    from .cam.cutters import parse_cutter
    from .cam.jobs import finishing_gcode
    from .cam.zigzag import FinishSettings

    # 0.05 mm: a 0.01 mm finish on a 100 mm part costs our planner ~100 s of CPU here (minutes
    # on a Pi); ask for it with --scallop or the bench setting when the part deserves it
    from .surface.uncertainty import DEFAULT_UNCERTAIN_MM

    opts = dict(cutter="ball6", scallop=0.05, dialect="linuxcnc", uncertain_mm=DEFAULT_UNCERTAIN_MM)
    opts.update(cam_options or {})
    try:
        settings = FinishSettings(parse_cutter(opts["cutter"]), scallop=opts["scallop"])
        cam = finishing_gcode(hm, settings, dialect=opts["dialect"], uncertain_mm=opts["uncertain_mm"])
    except InkSliceError as e:
        # no program, no outputs: a set without its G-code is not a job's result
        raise InkSliceError("finishing program", f"cannot be made: {e}") from None
    files["toolpath.gcode"] = cam.text.encode()
    job.diagnostics["toolpath"] = {
        "runtime_min": cam.runtime_s / 60,
        **{k: v for k, v in cam.summary.items() if isinstance(v, (int, float, str))},
    }
    return files


def write_outputs(job: Job, out_folder, cam_options=None, keep=()) -> list[str]:
    """Render every output in memory, then make OUT hold exactly them, at once
    (plus the entries named in `keep`: the daemon's scan inside its job folder)."""
    out = Path(out_folder)
    hm = job.heightmap
    files = {"heightmap.csv": outputs.heightmap_csv_text(hm).encode()}
    progress.stage("toolpath")
    files.update(toolpath_files(job, cam_options))
    progress.stage("writing outputs")
    if job.pipeline == "inkslice":
        from .surface.stl import heightmap_to_stl

        files["surface.stl"] = heightmap_to_stl(hm)
    summary = uncertainty_summary(job, (cam_options or {}).get("uncertain_mm"))
    if summary is not None:
        job.diagnostics["uncertainty"] = summary
        files[UNCERTAINTY_PNG] = plots.uncertainty_map(
            hm, summary["threshold_mm"], f"{job.scan_folder.name}: uncertainty per cell"
        )
    if job.reference is not None:
        surface = job.reference
        errs = {}
        for k, h in job.heightmaps.items():
            X, Y = h.grid()
            errs[k] = np.where(surface.inside(X, Y), np.abs(h.z - surface.height(X, Y)), np.nan)
        for k, err in errs.items():
            files[png_name(k)] = plots.error_map(
                err, job.heightmaps[k].x, job.heightmaps[k].y, f"{job.truth}: {label(k)}"
            )
    files["report.md"] = report_markdown(job).encode()
    files["report.json"] = (
        json.dumps(
            {
                "scan": str(job.scan_folder),
                "pipeline": job.pipeline,
                "method": job.method,
                "truth": job.truth,
                "statistics": job.stats,
                "timings": job.timings,
                "diagnostics": job.diagnostics,
                "notes": job.notes,
                "calibration": job.calibration,
            },
            indent=2,
            default=_jsonable,
        )
        + "\n"
    ).encode()
    atomicio.replace_folder(out, files, keep)
    return sorted(files)


def _jsonable(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def process_scan(scan_folder, out_folder, cam_options=None, keep=(), **options) -> dict:
    atomicio.check_output_folder(out_folder, is_output_name, keep)  # before the long work
    job = process(scan_folder, **options)
    written = write_outputs(job, out_folder, cam_options, keep)
    return {
        "outputs": written,
        "statistics": job.stats,
        "key": job.key,
        "method": job.method,
        "pipeline": job.pipeline,
        "truth": job.truth,
        "notes": job.notes,
        "out": str(out_folder),
    }
