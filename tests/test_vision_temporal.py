"""Monotone exposure: a bright thing on the ink that comes and goes is never part.

Seen from above, what stands out of the ink at one level still stands out at every lower
one. process.extract_waterlines reads each frame with the next lower frames beside it, and
a pixel counts as part only where they show part too: a blob seen in one or two frames,
then gone, is glare or flotsam, whatever it looks like in its own frame.
"""

import cv2
import numpy as np
from scan_helpers import MM_PER_PX, H, W, camera

from appliance.process import extract_waterlines
from appliance.scanfile import FrameRef, Scan, load_scan, write_frame, write_scan_json
from appliance.vision.camera import CameraModel
from appliance.vision.pipeline import WaterlineExtractor

LEVELS = (19, 17, 15, 13, 11, 9, 7, 5)
CENTRE = 30.0


def radius(level):
    """A steep-walled boss: its waterline widens 0.2 mm a level step."""
    return 10.0 + 0.1 * (20 - level)


def frame(level, blob=False):
    """The boss seen from above (0.25 mm a pixel, anti-aliased edge); with `blob`, a light grey
    blob (the part's colour, not the ink's blue) 3 mm across on the ink, overlapping the
    waterline on its +x side."""
    u, v = np.meshgrid(np.arange(W) + 0.0, np.arange(H) + 0.0)
    x, y = u * MM_PER_PX, (H - v) * MM_PER_PX
    d = radius(level) - np.hypot(x - CENTRE, y - CENTRE)
    cover = np.clip(0.5 + d / MM_PER_PX, 0, 1)
    ink, part = np.array([60, 20, 10.0]), np.array([220, 225, 230.0])
    img = np.clip(np.rint(ink + cover[..., None] * (part - ink)), 0, 255).astype(np.uint8)
    if blob:
        x_mm = CENTRE + radius(level) + 1.0
        cv2.circle(
            img,
            (round(x_mm / MM_PER_PX), round(H - CENTRE / MM_PER_PX)),
            round(1.5 / MM_PER_PX),
            (215, 215, 215),
            -1,
        )
    return img


def radial_error_mm(wl):
    pts = np.vstack(wl.loops)
    return np.abs(np.hypot(pts[:, 0] - CENTRE, pts[:, 1] - CENTRE) - radius(wl.level_mm))


def write_scan(folder, blobs):
    refs = []
    for k, level in enumerate(LEVELS, start=1):
        rel = f"frames/{k:04d}.png"
        write_frame(folder, rel, frame(level, level in blobs))
        refs.append(FrameRef(rel, float(level)))
    write_scan_json(Scan(folder, camera(), refs, {}))
    return load_scan(folder)


def test_a_blob_in_one_or_two_frames_does_not_become_part(tmp_path):
    blobs = (17, 13, 11)  # once alone, then in two frames running
    scan = write_scan(tmp_path, blobs)
    waterlines = extract_waterlines(scan)
    assert [wl.level_mm for wl in waterlines] == list(LEVELS)
    for wl in waterlines:  # within a pixel (0.25 mm): cut back to what the lower frames show
        assert radial_error_mm(wl).max() < MM_PER_PX, wl.level_mm
    # read on its own, each of those frames does take the blob for part
    for level in blobs:
        alone = WaterlineExtractor(scan.camera).extract(frame(level, blob=True), level)
        assert radial_error_mm(alone).max() > 1.0


def test_the_part_is_kept_as_the_lower_frames_confirm_it():
    """The part itself is confirmed in every frame (it only grows as the ink falls); the
    same frame with a blob is read right with the lower frames beside it, wrong without."""
    below = [(lv, frame(lv)) for lv in (11, 9)]
    assert radial_error_mm(WaterlineExtractor(camera()).extract(frame(13), 13, below=below)).max() < 0.1
    with_blob = frame(13, blob=True)
    assert radial_error_mm(WaterlineExtractor(camera()).extract(with_blob, 13, below=below)).max() < MM_PER_PX
    assert radial_error_mm(WaterlineExtractor(camera()).extract(with_blob, 13)).max() > 1.0


def test_a_blob_that_stays_is_not_judged_by_this_rule():
    """What the lower frames show in the same place is kept: the rule only ever removes what
    comes and goes (a blob in every frame is the part's business, not a transient's)."""
    below = [(lv, frame(lv, blob=True)) for lv in (11, 9)]
    wl = WaterlineExtractor(camera()).extract(frame(13, blob=True), 13, below=below)
    assert radial_error_mm(wl).max() > 1.0


BIG_W, BIG_H, BIG_MM = 2048, 1536, 0.08  # the bench's frame: a sliver is a speck of it


def big_camera():
    return CameraModel(
        BIG_W, BIG_H, np.array([[BIG_MM, 0, 0], [0, -BIG_MM, BIG_H * BIG_MM], [0, 0, 1]], float)
    )


def ridge(level, crest):
    """The ridge's plan (x, y mm per pixel) and how much of each pixel is part at `level`: 8 mm
    long along x at level 20, its crest at `crest`, its sides falling 1 mm per mm."""
    u, v = np.meshgrid(np.arange(BIG_W, dtype=np.float32), np.arange(BIG_H, dtype=np.float32))
    x, y = u * BIG_MM, (BIG_H - v) * BIG_MM
    d = np.minimum((crest - level) - np.abs(y - 60), 4 + 0.5 * (20 - level) - np.abs(x - 80))
    return x, y, np.clip(0.5 + d / BIG_MM, 0, 1)[..., None]


INK, LIT = np.array([60, 20, 10.0], np.float32), np.array([220, 225, 230.0], np.float32)


def ridge_frame(level, crest=20.3):
    """The ridge through a slightly blurred lens: at level 20 a sliver 0.6 mm (7 px) wide."""
    _, _, cover = ridge(level, crest)
    img = cv2.GaussianBlur(INK + cover * (LIT - INK), (0, 0), 1.3)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def ridge_scan(folder, frame_of, levels=(21, 20, 19, 18, 17)):
    refs = []
    for k, level in enumerate(levels, start=1):
        write_frame(folder, f"frames/{k:04d}.png", frame_of(level))
        refs.append(FrameRef(f"frames/{k:04d}.png", float(level)))
    write_scan_json(Scan(folder, big_camera(), refs, {}))
    return load_scan(folder)


def sliver_sides(waterlines, half_width):
    """How far the sliver's points (level 20, the middle 6 mm) are from its true sides."""
    assert [len(wl.loops) for wl in waterlines] == [0, 1, 1, 1, 1]
    sliver = waterlines[1].loops[0]
    return np.abs(np.abs(sliver[:, 1] - 60) - half_width)[np.abs(sliver[:, 0] - 80) < 3]


def test_a_top_first_showing_as_a_sliver_is_read_with_what_the_frames_below_taught(tmp_path):
    scan = ridge_scan(tmp_path, ridge_frame)
    # on its own, the sliver is too small a part of the frame to be told from the ink
    assert WaterlineExtractor(big_camera(), no_part="empty").extract(ridge_frame(20), 20).loops == []
    sides = sliver_sides(extract_waterlines(scan), 0.3)
    assert len(sides) > 100 and sides.max() < 0.05  # its sides 0.3 mm either side of the crest


def dim_crest_frame(level, crest=20.15, dim=(70, 80, 95)):
    """The ridge through a more blurred lens, its top 0.3 mm a face turned from the lamp:
    grey `dim` (BGR), just above the threshold the lit faces teach. At level 20 it is a
    sliver 0.3 mm (4 px) wide, blurred below that threshold, in the haze of a lamp."""
    x, y, cover = ridge(level, crest)
    top = np.clip(0.5 + (0.3 - np.abs(y - 60)) / BIG_MM, 0, 1)[..., None]  # the dim face
    part = LIT + top * (np.array(dim, np.float32) - LIT)
    haze = 20 * np.exp(-((x - 70) ** 2 + (y - 55) ** 2) / (2 * 25.0**2))[..., None]
    img = cv2.GaussianBlur(INK + cover * (part - INK) + (1 - cover) * haze, (0, 0), 2.0)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def test_a_top_fainter_than_the_threshold_is_read_with_a_split_learned_inside_the_part_below(tmp_path):
    scan = ridge_scan(tmp_path, dim_crest_frame)
    # the lit faces below teach a threshold the blurred sliver at level 20 never reaches
    lit = WaterlineExtractor(big_camera())
    lit.extract(dim_crest_frame(19), 19, below=[(18, dim_crest_frame(18)), (17, dim_crest_frame(17))])
    assert dim_crest_frame(20)[..., 2].max() < lit.split.threshold
    sides = sliver_sides(extract_waterlines(scan), 0.15)
    # its sides 0.15 mm either side of the crest, read a pixel wide: the blur that dims a
    # sliver also widens it where the profile crosses the split learned on it
    assert len(sides) > 100 and sides.max() < 1.5 * BIG_MM
