"""Render a whole scan folder for a known part, with its ground truth beside it.

The scan folder is exactly what the daemon would write on a real bench
(scan.json + frames/NNNN.png, docs/scan-format.md), so processing cannot tell
them apart. What only the simulator knows - the part, the TRUE levels after
displacement, the meniscus parameters, the rig and the effects - goes to
`<folder>.truth.json`, OUTSIDE the folder, so processing can never peek at it.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from .. import atomicio
from ..errors import SettingError
from ..scanfile import FrameRef, Scan, write_frame, write_scan_json
from . import surfaces as _surfaces
from .render import Effects, effects_preset, liquid_level, render_frame
from .rig import Rig


def scan_levels(surface, step_mm: float) -> list[float]:
    """Nominal levels from just above the part's top down to ~0.5 mm above the base.

    Levels sit on multiples of the step (as a stage stepping from a fixed home
    would), the first one the smallest multiple above the top.
    """
    if not (step_mm > 0 and math.isfinite(step_mm)):
        raise SettingError("step", f"the level step must be a positive number of mm, got {step_mm!r}")
    top = surface.z_max
    first = math.floor(top / step_mm + 1e-9) * step_mm + step_mm
    n = int(math.floor((first - 0.5) / step_mm + 1e-9)) + 1
    levels = [round(first - i * step_mm, 6) for i in range(n)]
    return [lv for lv in levels if lv >= 0.5 - 1e-9] or [round(first, 6)]


def truth_path(folder) -> Path:
    folder = Path(folder)
    return folder.parent / (folder.name + ".truth.json")


def render_scan(surface, folder, step_mm: float = 1.0, rig: Rig = None, effects=None,
                seed: int = 0, levels=None, progress=None) -> Scan:
    """Render frames at each level into `folder` and write scan.json and the truth file.

    surface: a Surface or its name; effects: an Effects or a preset name.
    Frame i uses the random stream default_rng([seed, i]), so any frame can be
    re-rendered on its own and scans are reproducible.
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
    frames, true_levels = [], []
    t0 = time.perf_counter()
    for i, lv in enumerate(levels):
        rel = f"frames/{i + 1:04d}.png"
        img = render_frame(surface, lv, rig, effects, np.random.default_rng([seed, i]))
        write_frame(folder, rel, img)
        frames.append(FrameRef(rel, lv))
        true_levels.append(liquid_level(surface, lv, rig, effects))
        if progress:
            progress(i + 1, len(levels))
    scan = Scan(folder, rig.camera_model(distorted=effects.lens_distortion), frames,
                extra={"tank": {"inner_area_mm2": float(rig.tank_area_mm2)},
                       "source": {"kind": "simulated", "renderer": "appliance.sim.render"}})
    write_scan_json(scan)
    truth = {
        "format": "inkslice.truth/1",
        "surface": surface.name,
        "scan": folder.name,
        "step_mm": step_mm,
        "seed": seed,
        "frames": [{"file": f.file, "level_nominal_mm": f.level_mm, "level_true_mm": t}
                   for f, t in zip(frames, true_levels)],
        "levels_true_mm": true_levels,
        "rig": rig.to_json(),
        "effects": effects.to_json(),
        "meniscus": {"enabled": effects.meniscus,
                     "capillary_length_mm": effects.capillary_length_mm,
                     "contact_angle_deg": effects.contact_angle_deg},
        "displacement": {"enabled": effects.displacement,
                         "tank_inner_area_mm2": float(rig.tank_area_mm2)},
        "render_seconds": round(time.perf_counter() - t0, 3),
    }
    atomicio.write_json(truth_path(folder), truth)
    return scan
