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


def error_map(
    err: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    title: str,
    vmax: float | None = None,
    units: str = "mm",
    size: int = 480,
) -> bytes:
    """Render |error| per cell; NaN cells grey. Row 0 of err is the smallest y (drawn at the bottom)."""
    canvas, _, _ = _field_picture(err, x, y, title, vmax, f"error, {units}", size)
    ok, buf = cv2.imencode(".png", canvas)
    return buf.tobytes()


def uncertainty_map(hm, threshold_mm: float, title: str, most: int = 8, size: int = 480) -> bytes:
    """Uncertainty per cell (the colour bar tops at 3 x the threshold, so everything above
    the threshold is in the upper two thirds), low-confidence regions boxed and numbered."""
    from .surface.confidence import low_confidence_regions

    u = np.where(hm.on_part, hm.sigma, np.nan)
    canvas, to_px, _ = _field_picture(
        u, hm.x, hm.y, title + f" (boxes: over {threshold_mm:g} mm)", 3 * threshold_mm, "1-sigma, mm", size
    )
    inside = [r for r in low_confidence_regions(hm, threshold_mm) if not r.edge]  # the edge: all round
    for i, r in enumerate(inside[:most], start=1):
        p0, p1 = to_px(r.xmin, r.ymax), to_px(r.xmax, r.ymin)
        cv2.rectangle(canvas, p0, p1, (255, 255, 255), 2)
        cv2.rectangle(canvas, p0, p1, (0, 0, 0), 1)
        _text(canvas, str(i), (p0[0] + 3, p0[1] + 14), 0.5, (255, 255, 255), 2)
        _text(canvas, str(i), (p0[0] + 3, p0[1] + 14), 0.5, (0, 0, 0), 1)
    ok, buf = cv2.imencode(".png", canvas)
    return buf.tobytes()


class _Labels:
    """Text put on a canvas, each at a place its box does not share with another (kept in .boxes)."""

    def __init__(self, canvas):
        self.canvas, self.boxes = canvas, []

    @staticmethod
    def size(text, scale):
        (w, h), base = cv2.getTextSize(text, _FONT, scale, 1)
        return w, h + base

    def put(self, text, x, y, scale=0.45, color=(30, 30, 30)):
        """`text` with its top-left corner at (x, y); returns its box (x0, y0, x1, y1)."""
        w, h = self.size(text, scale)
        _text(self.canvas, text, (int(x), int(y + h - 3)), scale, color)
        box = (int(x), int(y), int(x + w), int(y + h))
        self.boxes.append(box)
        return box


def overlaps(boxes) -> list[tuple]:
    """Pairs of boxes (x0, y0, x1, y1) that share pixels: for the test that labels never collide."""
    return [
        (a, b)
        for i, a in enumerate(boxes)
        for b in boxes[i + 1 :]
        if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]
    ]


def _fit_title(title, width, scale=0.55):
    """The title in at most two lines that fit `width` px, shrinking the type a little if needed."""
    words = title.split()
    for s in (scale, 0.5, 0.45, 0.4):
        lines, line = [], ""
        for w in words:
            trial = f"{line} {w}".strip()
            if _Labels.size(trial, s)[0] <= width or not line:
                line = trial
            else:
                lines.append(line)
                line = w
        lines.append(line)
        if len(lines) <= 2 and all(_Labels.size(l, s)[0] <= width for l in lines):
            return lines, s
    return [_cut(l, width, 0.4) for l in lines[:2]], 0.4


def _cut(text, width, scale):
    """`text` shortened with "..." until it fits `width` px."""
    while len(text) > 1 and _Labels.size(text, scale)[0] > width:
        text = text[:-4] + "..." if len(text) > 4 else text[:-1]
    return text


def _field_picture(err, x, y, title, vmax, bar_label, size):
    """-> (BGR canvas, mm -> canvas pixel function, the label boxes).

    The map keeps the part's proportions (the longer side is `size` px), so a round part is
    round; the colour scale has ticks in `bar_label`'s unit and its title above it; x and y
    extents are written outside the map where nothing else goes."""
    err = np.asarray(err, float)
    finite = np.isfinite(err)
    top = float(vmax) if vmax else (float(np.nanmax(err)) if finite.any() else 1.0)
    top = top if top > 0 else 1.0
    norm = np.where(finite, np.clip(err / top, 0, 1), 0)
    img8 = (norm * 255).astype(np.uint8)[::-1]  # y up on the page
    colour = cv2.applyColorMap(img8, cv2.COLORMAP_TURBO)
    colour[~finite[::-1]] = (200, 200, 200)
    span_x, span_y = max(float(x[-1] - x[0]), 1e-9), max(float(y[-1] - y[0]), 1e-9)
    w = size if span_x >= span_y else max(40, int(round(size * span_x / span_y)))
    h = size if span_y >= span_x else max(40, int(round(size * span_y / span_x)))
    colour = cv2.resize(colour, (w, h), interpolation=cv2.INTER_NEAREST)

    y_labels = [f"{y[-1]:.1f}", f"{y[0]:.1f}"]
    ticks = [f"{frac * top:.3g}" for frac in (0.0, 0.25, 0.5, 0.75, 1.0)]
    margin_l = 12 + max(_Labels.size(t, 0.45)[0] for t in y_labels + ["y mm"])
    bar_w, gap = 20, 18
    right = gap + bar_w + 8 + max(_Labels.size(t, 0.45)[0] for t in ticks)
    right = max(right, gap + _Labels.size(bar_label, 0.45)[0] + 6)
    width = margin_l + w + right
    lines, tscale = _fit_title(title, width - 16)
    line_h = _Labels.size("Ag", tscale)[1] + 4
    margin_t = 10 + line_h * len(lines) + _Labels.size(bar_label, 0.45)[1] + 10
    margin_b = 2 * _Labels.size("Ag", 0.45)[1] + 14
    canvas = np.full((margin_t + max(h, 120) + margin_b, width, 3), 255, np.uint8)
    canvas[margin_t : margin_t + h, margin_l : margin_l + w] = colour
    labels = _Labels(canvas)
    for i, line in enumerate(lines):
        labels.put(line, 8, 8 + i * line_h, tscale)
    # the map's extents: x under its corners, y beside them, the axis names in the free corner
    below = margin_t + h + 4
    labels.put(f"{x[0]:.1f}", margin_l, below)
    right_x = f"{x[-1]:.1f}"
    labels.put(right_x, margin_l + w - _Labels.size(right_x, 0.45)[0], below)
    labels.put(
        "x mm",
        margin_l + w // 2 - _Labels.size("x mm", 0.45)[0] // 2,
        below + _Labels.size("Ag", 0.45)[1] + 2,
    )
    labels.put(y_labels[0], 6, margin_t)
    labels.put(y_labels[1], 6, margin_t + h - _Labels.size(y_labels[1], 0.45)[1])
    if h >= 3 * _Labels.size("Ag", 0.45)[1]:
        labels.put("y mm", 6, margin_t + h // 2 - 8)
    # the colour scale: its unit above, ticks beside, top = the largest value
    bx = margin_l + w + gap
    bar = cv2.applyColorMap(
        np.linspace(255, 0, h).astype(np.uint8)[:, None].repeat(bar_w, 1), cv2.COLORMAP_TURBO
    )
    canvas[margin_t : margin_t + h, bx : bx + bar_w] = bar
    labels.put(bar_label, bx - 4, margin_t - _Labels.size(bar_label, 0.45)[1] - 4)
    tick_h = _Labels.size("0", 0.45)[1]
    step = max(1, int(np.ceil(5 * (tick_h + 2) / max(h, 1))))  # a short map gets fewer ticks
    for i, (frac, text) in enumerate(zip((0.0, 0.25, 0.5, 0.75, 1.0), ticks)):
        if i % step and i != 4:
            continue
        yy = margin_t + int((1 - frac) * (h - 1)) - tick_h // 2
        yy = min(max(yy, margin_t), margin_t + h - tick_h)
        cv2.line(canvas, (bx + bar_w, yy + tick_h // 2), (bx + bar_w + 4, yy + tick_h // 2), (30, 30, 30), 1)
        labels.put(text, bx + bar_w + 8, yy)

    def to_px(xm, ym):
        fx = (xm - x[0]) / span_x
        fy = (ym - y[0]) / span_y
        return (int(round(margin_l + fx * (w - 1))), int(round(margin_t + (1 - fy) * (h - 1))))

    return canvas, to_px, labels.boxes
