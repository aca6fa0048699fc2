"""The waterline extractor's options (pipeline.WaterlineExtractor), their defaults and checks.

All are keywords of WaterlineExtractor(camera, **options):

  channel: "auto" (chosen on the first frame), 0, 1 or 2 (B, G, R);
  roi: (x0, y0, x1, y1) pixels of the tank in the frame (default: the frame);
  band: read only a band around last frame's waterline (default True);
  band_px: half-width of that band in pixels (default 13, ~1 mm);
  tile_px: tile side of the band (default 24);
  min_area_px: smallest island or hole kept, pixels (default 60);
  min_new_island_px: smallest island kept that is not connected to the
    part of the previous frame (default 400; min_area_px when lower frames confirm it);
  min_contrast: smallest part/ink grey-level difference trusted (default 24);
  half_width: samples each side of the contour along the normal (default 4);
  threshold_fraction: where the part/ink threshold sits between the ink and
    the part levels (default 0.3: near the flat ink, below shaded part faces);
  no_part: "raise" (default: NoPartError) or "empty" (an empty Waterline) for
    a frame with no part above the liquid - a scan's top frames are like that;
  raised_shores: the lower frames also confirm part as edges standing above the ink
    would have shown in this frame (support.Raised; default False: a scan read again
    when a pocket may have held ink, waterlines.py).
"""

from __future__ import annotations

from ..errors import SettingError

DEFAULTS = dict(
    channel="auto",
    roi=None,
    band=True,
    band_px=13,
    tile_px=24,
    min_area_px=60,
    min_new_island_px=400,
    min_contrast=24,
    half_width=4,
    threshold_fraction=0.3,
    no_part="raise",
    raised_shores=False,
)


def extractor_options(options: dict) -> dict:
    """DEFAULTS with `options` over them; a SettingError names an unknown or bad one."""
    unknown = set(options) - set(DEFAULTS)
    if unknown:
        raise SettingError("vision", f"unknown WaterlineExtractor option(s): {', '.join(sorted(unknown))}")
    opts = {**DEFAULTS, **options}
    if opts["no_part"] not in ("raise", "empty"):
        raise SettingError("vision.no_part", f"must be 'raise' or 'empty', got {opts['no_part']!r}")
    return opts


def check_roi(roi, width: int, height: int) -> tuple[int, int, int, int]:
    """The region of interest as (x0, y0, x1, y1) pixels inside the frame (default: all of it)."""
    if roi is None:
        return (0, 0, width, height)
    x0, y0, x1, y1 = (int(v) for v in roi)
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height) or x1 - x0 < 16 or y1 - y0 < 16:
        raise SettingError("vision.roi", f"{roi!r} is not a rectangle inside the {width}x{height} frame")
    return (x0, y0, x1, y1)
