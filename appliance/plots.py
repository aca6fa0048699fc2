"""Small PNG pictures drawn with OpenCV (no plotting library on the bench box).

error_map: a height-map-shaped array of errors as a colour map, with a title,
axis extents and a colour bar, like the dissertation's figures 5-1..5-16.
uncertainty_map: the same for each cell's uncertainty, with the low-confidence
regions boxed and numbered as the report and the G-code header list them.
"""
from __future__ import annotations

import cv2
import numpy as np

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _text(img, text, org, scale=0.5, color=(30, 30, 30), thickness=1):
    cv2.putText(img, text, org, _FONT, scale, color, thickness, cv2.LINE_AA)


def error_map(err: np.ndarray, x: np.ndarray, y: np.ndarray, title: str,
              vmax: float | None = None, units: str = "mm", size: int = 480) -> bytes:
    """Render |error| per cell; NaN cells grey. Row 0 of err is the smallest y (drawn at the bottom)."""
    canvas, _ = _field_picture(err, x, y, title, vmax, f"|err| {units}", size)
    ok, buf = cv2.imencode(".png", canvas)
    return buf.tobytes()


def uncertainty_map(hm, threshold_mm: float, title: str, most: int = 8, size: int = 480) -> bytes:
    """Uncertainty per cell (the colour bar tops at 3 x the threshold, so everything above
    the threshold is in the upper two thirds), low-confidence regions boxed and numbered."""
    from .surface.uncertainty import low_confidence_regions
    u = np.where(hm.on_part, hm.sigma, np.nan)
    canvas, to_px = _field_picture(u, hm.x, hm.y, title + f" (boxes: over {threshold_mm:g} mm)",
                                   3 * threshold_mm, "1-sigma mm", size)
    for i, r in enumerate(low_confidence_regions(hm, threshold_mm)[:most], start=1):
        p0, p1 = to_px(r.xmin, r.ymax), to_px(r.xmax, r.ymin)
        cv2.rectangle(canvas, p0, p1, (255, 255, 255), 2)
        cv2.rectangle(canvas, p0, p1, (0, 0, 0), 1)
        _text(canvas, str(i), (p0[0] + 3, p0[1] + 14), 0.5, (255, 255, 255), 2)
        _text(canvas, str(i), (p0[0] + 3, p0[1] + 14), 0.5, (0, 0, 0), 1)
    ok, buf = cv2.imencode(".png", canvas)
    return buf.tobytes()


def _field_picture(err, x, y, title, vmax, bar_label, size):
    """-> (BGR canvas, mm -> canvas pixel function)."""
    err = np.asarray(err, float)
    finite = np.isfinite(err)
    top = float(vmax) if vmax else (float(np.nanmax(err)) if finite.any() else 1.0)
    top = top if top > 0 else 1.0
    norm = np.where(finite, np.clip(err / top, 0, 1), 0)
    img8 = (norm * 255).astype(np.uint8)[::-1]                 # y up on the page
    colour = cv2.applyColorMap(img8, cv2.COLORMAP_TURBO)
    colour[~finite[::-1]] = (200, 200, 200)
    colour = cv2.resize(colour, (size, size), interpolation=cv2.INTER_NEAREST)

    margin_l, margin_t, margin_r, margin_b = 60, 40, 110, 45
    canvas = np.full((size + margin_t + margin_b, size + margin_l + margin_r, 3), 255, np.uint8)
    canvas[margin_t:margin_t + size, margin_l:margin_l + size] = colour
    _text(canvas, title, (margin_l, 25), 0.55)
    _text(canvas, f"x {x[0]:.1f} .. {x[-1]:.1f} mm", (margin_l, margin_t + size + 30))
    _text(canvas, f"y {y[0]:.0f}", (5, margin_t + size))
    _text(canvas, f"y {y[-1]:.0f}", (5, margin_t + 12))
    # colour bar
    bar = cv2.applyColorMap(np.linspace(255, 0, size).astype(np.uint8)[:, None].repeat(20, 1), cv2.COLORMAP_TURBO)
    bx = margin_l + size + 15
    canvas[margin_t:margin_t + size, bx:bx + 20] = bar
    for frac in (0.0, 0.25, 0.5, 0.75, 1.0):
        yy = margin_t + int((1 - frac) * (size - 1))
        _text(canvas, f"{frac * top:.3g}", (bx + 25, yy + 5), 0.45)
    _text(canvas, bar_label, (bx - 5, margin_t + size + 30), 0.45)

    def to_px(xm, ym):
        fx = (xm - x[0]) / max(x[-1] - x[0], 1e-9)
        fy = (ym - y[0]) / max(y[-1] - y[0], 1e-9)
        return (int(round(margin_l + fx * (size - 1))), int(round(margin_t + (1 - fy) * (size - 1))))
    return canvas, to_px
