"""Going back into a level step in which a face came out at once (vision/refine.py)."""

import numpy as np

from appliance.vision.camera import CameraModel
from appliance.vision.refine import face_bracket, mask_pixel_mm, next_refinement, surfaced_faces

PX = 0.5  # mm per mask pixel


def disc(cx, cy, r, shape=(200, 200)):
    y, x = np.mgrid[: shape[0], : shape[1]]
    return (x - cx) ** 2 + (y - cy) ** 2 <= r * r


def bisect(upper, lower, faces, appears_below, resolution=0.1):
    """Run the refinement as the runner does, on a bench where face i shows below appears_below[i]."""
    seen = []
    while (level := next_refinement(upper, lower, faces, seen, resolution)) is not None:
        mask = np.zeros_like(faces[0])
        for face, height in zip(faces, appears_below):
            if level < height:
                mask |= face
        seen.append((level, mask))
    return seen


def test_a_wide_piece_out_at_once_is_a_face_a_band_of_descending_waterline_is_not():
    before = disc(100, 100, 20)
    band = disc(100, 100, 24)  # the waterline moved 2 mm outwards all round
    assert surfaced_faces(before, band, PX) == []
    with_face = band | disc(160, 100, 12)  # and a 12 mm wide plateau came out beside it
    faces = surfaced_faces(before, with_face, PX)
    assert len(faces) == 1 and faces[0][100, 160] and not faces[0][100, 100]


def test_no_faces_without_a_frame_above():
    assert surfaced_faces(None, disc(100, 100, 30), PX) == []


def test_bisection_brackets_a_face_to_the_resolution_in_four_frames_of_a_1_mm_step():
    face = disc(100, 100, 30)
    seen = bisect(8.0, 7.0, [face], [7.38])
    assert [lv for lv, _ in seen] == [7.5, 7.25, 7.375, 7.4375]
    lo, hi = face_bracket(face, 8.0, 7.0, seen)
    assert lo < 7.38 <= hi and hi - lo <= 0.1


def test_one_frame_narrows_every_face_it_falls_between():
    a, b = disc(50, 50, 25), disc(150, 150, 25)
    seen = bisect(8.0, 7.0, [a, b], [7.9, 7.1])
    for face, height in ((a, 7.9), (b, 7.1)):
        lo, hi = face_bracket(face, 8.0, 7.0, seen)
        assert lo < height <= hi and hi - lo <= 0.1
    assert len(seen) == 7  # 4 each, the first one shared


def test_a_face_counts_out_when_most_of_it_shows():
    face = disc(100, 100, 30)
    half_out = face & (np.mgrid[:200, :200][1] < 100 + 10)
    assert face_bracket(face, 8.0, 7.0, [(7.5, half_out)]) == (7.5, 8.0)
    assert face_bracket(face, 8.0, 7.0, [(7.5, face & (np.mgrid[:200, :200][1] < 80))]) == (7.0, 7.5)


def test_refinement_off_or_done_asks_for_nothing():
    face = disc(100, 100, 30)
    assert next_refinement(8.0, 7.0, [], []) is None
    assert next_refinement(7.05, 7.0, [face], []) is None


def test_mask_pixels_are_the_frame_pixels_scaled_to_the_mask():
    camera = CameraModel(2048, 1536, np.diag([0.08, 0.08, 1.0]))
    assert np.isclose(mask_pixel_mm(camera, (192, 256)), 0.08 * 2048 / 256)
