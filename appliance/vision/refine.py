"""Where to look again: faces that came out of the ink all at once.

An ink that does not wet the part (contact angle theta > 0) stands in a depression
d = 2 l_c sin(theta / 2) over a face flatter than theta: the face stays under until the ink
is d above it, then comes out in one piece between two frames, with no waterline ever
crossing it (the second ink of the virtual bench: d = 1.38 mm). Those two frames only say
that the face's apparent height lies somewhere in their level step, and no fit of them can
say where (processing places it in the middle: up to half a step out, 0.08-0.27 mm on the
bench's faces). So the scan goes back: the runner raises the ink into that step again and
bisects it, frame by frame, until each face is known to RESOLUTION_MM.

Both the daemon's runner and the virtual bench's render loop (sim/scanrender.py) ask these
functions, with the part masks of vision/part.py, so a rendered scan holds the frames a real
one would hold. The extra frames are ordinary level frames in scan.json.

What counts as a face: a piece of the part newly out of the ink whose inscribed circle is at
least FACE_MIN_WIDTH_MM across. A level step of s uncovers a band s / tan(slope) wide on a
slope; 8 mm is a slope under 7 deg at 1 mm steps. Narrower pieces are the ordinary descent of
a waterline, which the frames already follow.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

FACE_MIN_WIDTH_MM = 8.0  # inscribed diameter of a newly exposed piece that makes it a face
RESOLUTION_MM = 0.1  # bisect until every face's bracket is at most this tall
OUT_FRACTION = 0.5  # a face counts as out of the ink in a frame showing this much of it
EPS = 1e-6


def surfaced_faces(
    before: np.ndarray, after: np.ndarray, pixel_mm: float, min_width_mm: float = FACE_MIN_WIDTH_MM
) -> list[np.ndarray]:
    """The faces that came out between two frames: pieces of `after & ~before` (part masks
    of the frame above and the one below) at least `min_width_mm` wide. `pixel_mm`: the
    masks' pixel size on the liquid plane."""
    if before is None or before.shape != after.shape:
        return []
    new = after & ~before
    labels, n = ndimage.label(new)
    faces = []
    for i in range(1, n + 1):
        piece = labels == i
        inscribed = 2.0 * float(np.max(ndimage.distance_transform_edt(np.pad(piece, 1)))) * pixel_mm
        if inscribed >= min_width_mm:
            faces.append(piece)
    return faces


def face_bracket(face: np.ndarray, upper: float, lower: float, seen) -> tuple[float, float]:
    """(lo, hi): the face's apparent height lies in (lo, hi], from the bracket's own frames
    (out at `lower`, under at `upper`) and the refinement frames `seen` [(level, mask)]."""
    lo, hi = lower, upper
    area = max(int(np.count_nonzero(face)), 1)
    for level, mask in seen:
        if not lower < level < upper:
            continue
        if np.count_nonzero(mask & face) >= OUT_FRACTION * area:
            lo = max(lo, level)
        else:
            hi = min(hi, level)
    return lo, max(hi, lo)


def next_refinement(
    upper: float, lower: float, faces, seen, resolution_mm: float = RESOLUTION_MM
) -> float | None:
    """The next level to capture between `upper` (faces under) and `lower` (faces out), or
    None when every face's bracket is at most `resolution_mm` tall. Bisects the widest
    bracket first; one frame narrows every face whose bracket it falls in."""
    widest = None
    for face in faces:
        lo, hi = face_bracket(face, upper, lower, seen)
        if hi - lo > resolution_mm + EPS and (widest is None or hi - lo > widest[1] - widest[0]):
            widest = (lo, hi)
    if widest is None:
        return None
    level = round(0.5 * (widest[0] + widest[1]), 6)
    taken = {round(lv, 6) for lv, _ in seen} | {round(upper, 6), round(lower, 6)}
    return None if level in taken else level


def mask_pixel_mm(camera, mask_shape) -> float:
    """The size on the liquid plane of one pixel of a part mask `mask_shape` (find_part's,
    scaled from the camera's frame), at the frame's centre."""
    return camera.pixel_mm() * camera.width / mask_shape[1]
