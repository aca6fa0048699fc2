"""Render a whole scan folder for a known part, with its ground truth beside it.

The scan folder is exactly what the daemon would write on a real bench
(scan.json + frames/NNNN.png, docs/scan-format.md), so processing cannot tell
them apart. What only the simulator knows - the part, the TRUE levels after
displacement, the meniscus parameters, the rig and the effects - goes to
`<folder>.truth.json`, OUTSIDE the folder, so processing can never peek at it.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from .. import atomicio
from ..errors import SettingError
from ..scanfile import FrameRef, Scan, load_scan, read_frame, write_frame, write_scan_json
from ..vision.part import find_part
from ..vision.refine import RESOLUTION_MM, mask_pixel_mm, next_refinement, surfaced_faces
from . import surfaces as _surfaces
from .effects import Effects, effects_preset
from .partgrid import curvature_grid, surface_grid
from .render import liquid_level, render_frame
from .rig import Rig, pixel_map
from .truth import truth_path


def scan_levels(surface, step_mm: float, above_mm: float = 0.0) -> list[float]:
    """Nominal levels from just above the part's top down to ~0.5 mm above the base.

    Levels sit on multiples of the step (as a stage stepping from a fixed home
    would), the first one the smallest multiple above the top, or above the top and
    `above_mm` (how far an ink that does not wet flat faces stands over a top it has
    left: that frame still shows the part).
    """
    if not (step_mm > 0 and math.isfinite(step_mm)):
        raise SettingError("step", f"the level step must be a positive number of mm, got {step_mm!r}")
    top = surface.z_max + max(above_mm, 0.0)
    first = math.floor(top / step_mm + 1e-9) * step_mm + step_mm
    n = int(math.floor((first - 0.5) / step_mm + 1e-9)) + 1
    levels = [round(first - i * step_mm, 6) for i in range(n)]
    return [lv for lv in levels if lv >= 0.5 - 1e-9] or [round(first, 6)]


_FORKED = {}  # what forked workers inherit (a Surface holds closures: not picklable)


def _render_one(job):
    surface, folder, rel, level, rig, effects, seed, i = job
    if surface is None:
        surface = _FORKED["surface"]
    img = render_frame(surface, level, rig, effects, np.random.default_rng([seed, i]))
    write_frame(folder, rel, img)
    return liquid_level(surface, level, rig, effects)


def _render_all(surface, jobs, rig, effects, workers, progress=None) -> list[float]:
    """Render `jobs` (see _render_one), in forked workers when asked; -> their true levels."""
    true_levels = []
    if workers and workers > 1 and len(jobs) > 1:
        import multiprocessing as mp

        pixel_map(rig, effects.lens_distortion)
        surface_grid(surface)
        if effects.meniscus and effects.contact_line_curvature:
            curvature_grid(surface)
        _FORKED["surface"] = surface
        try:
            pool = mp.get_context("fork").Pool(min(workers, len(jobs)))
        finally:
            _FORKED.clear()  # the children have their copy; keep no reference here
        with pool:
            for i, t in enumerate(pool.imap(_render_one, [(None,) + j[1:] for j in jobs])):
                true_levels.append(t)
                if progress:
                    progress(i + 1, len(jobs))
    else:
        for i, job in enumerate(jobs):
            true_levels.append(_render_one(job))
            if progress:
                progress(i + 1, len(jobs))
    return true_levels


def render_scan(
    surface,
    folder,
    step_mm: float = 1.0,
    rig: Rig = None,
    effects=None,
    seed: int = 0,
    levels=None,
    progress=None,
    workers: int = 1,
    refine_mm: float = 0.0,
) -> Scan:
    """Render frames at each level into `folder` and write scan.json and the truth file.

    surface: a Surface or its name; effects: an Effects or a preset name.
    Frame i uses the random stream default_rng([seed, i]), so any frame can be
    re-rendered on its own and scans are reproducible - also with `workers` > 1,
    which renders frames in forked processes (the per-rig and per-part caches
    are built first, so the children inherit them instead of rebuilding them).
    refine_mm > 0: then the steps in which a face came out at once are bisected to
    that, as the daemon's runner does (refine_scan).
    """
    if isinstance(surface, str):
        surface = _surfaces.get(surface)
    if isinstance(effects, str):
        effects = effects_preset(effects)
    rig = rig or Rig()
    effects = effects or Effects()
    folder = Path(folder)
    if levels is None:
        levels = scan_levels(surface, step_mm)
    levels = [float(lv) for lv in levels]
    if not levels:
        raise SettingError("levels", "no levels to render")
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    jobs = [
        (surface, folder, f"frames/{i + 1:04d}.png", lv, rig, effects, seed, i) for i, lv in enumerate(levels)
    ]
    frames = [FrameRef(j[2], j[3]) for j in jobs]
    true_levels = _render_all(surface, jobs, rig, effects, workers, progress)
    extra = {"source": {"kind": "simulated", "renderer": "appliance.sim.render"}}
    if effects.displacement:
        # A real bench always displaces ink, so the daemon always writes the tank;
        # a simulated bench only when it simulates the effect, else processing
        # would "correct" levels that never dropped.
        extra["tank"] = {"inner_area_mm2": float(rig.tank_area_mm2), "surface_falls": True}
    scan = Scan(folder, rig.camera_model(distorted=effects.lens_distortion), frames, extra=extra)
    write_scan_json(scan)
    truth = {
        "format": "inkslice.truth/1",
        "surface": surface.name,
        "scan": folder.name,
        "step_mm": step_mm,
        "seed": seed,
        "frames": [
            {"file": f.file, "level_nominal_mm": f.level_mm, "level_true_mm": t}
            for f, t in zip(frames, true_levels)
        ],
        "levels_true_mm": true_levels,
        "rig": rig.to_json(),
        "effects": effects.to_json(),
        "meniscus": {
            "enabled": effects.meniscus,
            "capillary_length_mm": effects.capillary_length_mm,
            "contact_angle_deg": effects.contact_angle_deg,
            "contact_line_curvature": effects.contact_line_curvature,
        },
        "displacement": {"enabled": effects.displacement, "tank_inner_area_mm2": float(rig.tank_area_mm2)},
        "render_seconds": round(time.perf_counter() - t0, 3),
    }
    atomicio.write_json(truth_path(folder), truth)
    if refine_mm > 0:
        refine_scan(surface, folder, refine_mm, rig, effects, seed, workers)
        scan = load_scan(folder)
    return scan


def refine_scan(
    surface,
    folder,
    refine_mm: float = RESOLUTION_MM,
    rig: Rig = None,
    effects=None,
    seed: int = 0,
    workers: int = 1,
) -> int:
    """The render loop's second pass, the runner's refinement (daemon/runner.py) on a rendered
    scan: find the part in each frame (vision/part.py), ask vision/refine.py where a face came
    out at once between two levels, render the frames it asks for, and again until it asks for
    none. Steps are bisected side by side, one round of frames at a time. The frames go into
    scan.json (marked `refines`, as the runner marks them) and their true levels into the
    truth file. A step already refined is not asked again. -> the number of frames added."""
    if isinstance(surface, str):
        surface = _surfaces.get(surface)
    if isinstance(effects, str):
        effects = effects_preset(effects)
    rig, effects, folder = rig or Rig(), effects or Effects(), Path(folder)
    scan = load_scan(folder)
    truth = json.loads(truth_path(folder).read_text())
    part = {}

    def mask(ref):
        if ref.file not in part:
            part[ref.file] = find_part(read_frame(scan, ref), scan.camera, ref.level_mm)
        return part[ref.file]

    plan = sorted((f for f in scan.frames if "refines" not in f.extra), key=lambda f: -f.level_mm)
    steps = []
    for above, below in zip(plan, plan[1:]):
        faces = surfaced_faces(mask(above), mask(below), mask_pixel_mm(scan.camera, mask(below).shape))
        if faces:
            seen = [
                (f.level_mm, mask(f))
                for f in scan.frames
                if f.extra.get("refines") == [above.level_mm, below.level_mm]
            ]
            steps.append((above.level_mm, below.level_mm, faces, seen))
    added = 0
    while True:
        asks = [(st, next_refinement(st[0], st[1], st[2], st[3], refine_mm)) for st in steps]
        asks = [(st, lv) for st, lv in asks if lv is not None]
        if not asks:
            return added
        n = len(scan.frames)
        jobs = [
            (surface, folder, f"frames/{n + i + 1:04d}.png", lv, rig, effects, seed, n + i)
            for i, (_, lv) in enumerate(asks)
        ]
        true_levels = _render_all(surface, jobs, rig, effects, workers)
        for (st, lv), job, t in zip(asks, jobs, true_levels):
            ref = FrameRef(job[2], lv, {"refines": [st[0], st[1]]})
            scan.frames.append(ref)
            st[3].append((lv, mask(ref)))
            truth["frames"].append({"file": ref.file, "level_nominal_mm": lv, "level_true_mm": t})
            truth["levels_true_mm"].append(t)
        added += len(asks)
        write_scan_json(scan)
        atomicio.write_json(truth_path(folder), truth)
