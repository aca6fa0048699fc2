"""`inkslice process SCAN -o OUT`: a scan folder in, a job's outputs out.

Two pipelines share this entry point (pipelines.py): "inkslice", ours (sub-pixel
waterlines, a regularised fit, then a cutter-compensated finishing program from cam/),
and "seed", the seed method of the 2013 dissertation with its own G-code format
(cam/seed.py). report.py writes report.md.

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
from pathlib import Path

import numpy as np

from . import atomicio, outputs, plots, progress
from .cam.seed import seed_gcode
from .errors import InkSliceError, SettingError
from .pipelines import (  # noqa: F401 (callers import these from here)
    LABELS,
    OUR_METHODS,
    PIPELINES,
    Job,
    extract_waterlines,
    label,
    meniscus_model,
    run_inkslice,
    run_seed,
)
from .report import UNCERTAINTY_PNG, png_name, report_markdown, uncertainty_summary
from .scanfile import check_frames, load_scan
from .surface import seed as seed_methods
from .surface.heightmap import HeightMap
from .surface.stats import seed_statistics

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
    waterlines_of=extract_waterlines,
    pair_memo=None,
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

    ours = pipeline == "inkslice" or compare  # the seed method corrects neither
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
        hms, job.diagnostics, _ = run_inkslice(
            scan, methods, grid_n, spacing_mm, displacement, meniscus, waterlines_of, pair_memo
        )
        job.heightmaps.update(hms)
        job.notes += [
            f"{label('inkslice:' + m)}: {n}"
            for m in methods
            for n in job.diagnostics[m].get("held_notes", []) + job.diagnostics[m]["base_notes"]
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


def toolpath_files(job: Job, cam_options=None) -> dict:
    """G-code for the chosen height map: ours, and the dissertation's format beside it."""
    hm = job.heightmap
    files = {"toolpath-dissertation.gcode": seed_gcode(hm).encode()}
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
