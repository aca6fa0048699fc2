"""Height-map thumbnails for the job list: heightmap.csv (x,y,z rows) drawn as a small picture.

Drawn by the web from the job's own output, once per version of it (the file's size and time
name the cached PNG under DATA/web/thumbs), so the list costs the daemon nothing. Low is dark
blue, high is yellow, as on the dashboard's live map; cells without a height stay dark.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..atomicio import write_bytes

SIZE = 96


def thumbnail(csv_path: Path, cache: Path, job_id: str) -> Path | None:
    st = csv_path.stat()
    out = cache / f"{job_id}-{st.st_size}-{int(st.st_mtime)}.png"
    if out.is_file():
        return out
    png = render(csv_path)
    if png is None:
        return None
    cache.mkdir(parents=True, exist_ok=True)
    for old in cache.glob(f"{job_id}-*.png"):
        old.unlink(missing_ok=True)
    write_bytes(out, png)
    return out


def render(csv_path: Path) -> bytes | None:
    try:
        xyz = np.loadtxt(csv_path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError):
        return None
    if xyz.shape[0] < 1 or xyz.shape[1] < 3:
        return None
    xs, ys = np.unique(xyz[:, 0]), np.unique(xyz[:, 1])
    grid = np.full((len(ys), len(xs)), np.nan)
    grid[np.searchsorted(ys, xyz[:, 1]), np.searchsorted(xs, xyz[:, 0])] = xyz[:, 2]
    ok = np.isfinite(grid)
    if not ok.any():
        return None
    lo, hi = np.nanmin(grid), np.nanmax(grid)
    t = np.where(ok, (grid - lo) / (hi - lo) if hi > lo else 1.0, 0.0)
    hsv = np.zeros(grid.shape + (3,), np.uint8)
    hsv[..., 0] = ((240 - 200 * t) / 2).astype(np.uint8)  # OpenCV's hue is 0..180
    hsv[..., 1] = 190
    hsv[..., 2] = np.where(ok, 110 + 145 * t, 30).astype(np.uint8)
    img = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[::-1]  # y up, as seen from above
    # the map's own aspect (a round part stays round) inside a square
    h, w = img.shape[:2]
    scale = SIZE / max(h, w)
    img = cv2.resize(
        img, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_NEAREST
    )
    canvas = np.full((SIZE, SIZE, 3), (42, 27, 13), np.uint8)
    y0, x0 = (SIZE - img.shape[0]) // 2, (SIZE - img.shape[1]) // 2
    canvas[y0 : y0 + img.shape[0], x0 : x0 + img.shape[1]] = img
    ok, buf = cv2.imencode(".png", canvas)
    return buf.tobytes() if ok else None
