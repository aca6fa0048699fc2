"""A tiny hand-made scan for tests that must not depend on the renderer.

A cone (apex 20 mm, slope 1:1) seen orthographically at 0.25 mm per pixel:
its waterline at level L is a circle of radius 20 - L about (30, 30) mm.
The edge is anti-aliased by a linear ramp so its 50 % grey crossing is exact.
"""

import numpy as np

from appliance.scanfile import FrameRef, Scan, write_frame, write_scan_json
from appliance.vision.camera import CameraModel

MM_PER_PX = 0.25
W, H = 240, 240


def camera():
    # pixel (u, v) -> (x, y) mm; y up, so v runs down the page
    Hm = np.array([[MM_PER_PX, 0, 0], [0, -MM_PER_PX, H * MM_PER_PX], [0, 0, 1]], float)
    return CameraModel(W, H, Hm)


def cone_frame(level):
    u, v = np.meshgrid(np.arange(W) + 0.0, np.arange(H) + 0.0)
    x, y = u * MM_PER_PX, (H - v) * MM_PER_PX
    d = (20 - level) - np.hypot(x - 30, y - 30)  # mm inside the waterline
    cover = np.clip(0.5 + d / MM_PER_PX, 0, 1)
    ink, part = np.array([60, 20, 10.0]), np.array([220, 225, 230.0])
    img = ink + cover[..., None] * (part - ink)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def write_cone_scan(folder, levels=(19, 17, 15, 13, 11, 9, 7, 5)):
    frames = []
    for k, level in enumerate(levels, start=1):
        rel = f"frames/{k:04d}.png"
        write_frame(folder, rel, cone_frame(level))
        frames.append(FrameRef(rel, float(level)))
    scan = Scan(folder, camera(), frames, {"note": "unknown keys are kept"})
    write_scan_json(scan)
    return scan
