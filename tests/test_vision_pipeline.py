"""WaterlineExtractor on synthetic frames with known waterlines."""

import cv2
import numpy as np
import pytest
from test_vision_synth import disc, draw, grid, pixel_camera, ring, to_pixels

from appliance.errors import InkSliceError, ScanError
from appliance.vision.pipeline import AllPartError, FrameError, NoPartError, WaterlineExtractor
from appliance.vision.types import signed_area

W, H = 320, 240


def radial_error(loop, cx, cy, r, h=H):
    uv = to_pixels(loop, h)
    return np.hypot(uv[:, 0] - cx, uv[:, 1] - cy) - r


def test_disc_is_found_to_a_tenth_of_a_pixel_and_runs_ccw():
    u, v = grid(W, H)
    wl = WaterlineExtractor(pixel_camera(W, H)).extract(draw(disc(u, v, 161.3, 117.8, 70.4)), 12.0)
    assert wl.level_mm == 12.0
    assert len(wl.loops) == 1
    loop = wl.loops[0]
    err = radial_error(loop, 161.3, 117.8, 70.4)
    assert len(loop) > 0.9 * 2 * np.pi * 70  # about one point per boundary pixel
    assert np.sqrt(np.mean(err**2)) < 0.1
    assert np.abs(err).max() < 0.3
    assert signed_area(loop) > 0


def test_ring_has_an_outer_ccw_loop_and_a_cw_hole():
    u, v = grid(W, H)
    wl = WaterlineExtractor(pixel_camera(W, H)).extract(draw(ring(u, v, 160, 120, 30.2, 90.7)), 5.0)
    areas = sorted(signed_area(lp) for lp in wl.loops)
    assert len(areas) == 2
    assert areas[0] == pytest.approx(-np.pi * 30.2**2, rel=0.01)
    assert areas[1] == pytest.approx(np.pi * 90.7**2, rel=0.01)
    for lp in wl.loops:
        r = 30.2 if signed_area(lp) < 0 else 90.7
        assert np.sqrt(np.mean(radial_error(lp, 160, 120, r) ** 2)) < 0.1


def test_two_islands_and_an_island_in_a_hole():
    u, v = grid(W, H)
    d = np.maximum(ring(u, v, 100, 120, 35, 70), disc(u, v, 100, 120, 15))
    d = np.maximum(d, disc(u, v, 250, 100, 40))
    wl = WaterlineExtractor(pixel_camera(W, H)).extract(draw(d), 1.0)
    outer = [lp for lp in wl.loops if signed_area(lp) > 0]
    holes = [lp for lp in wl.loops if signed_area(lp) < 0]
    assert len(outer) == 3 and len(holes) == 1
    centres = sorted(tuple(np.round(to_pixels(lp, H).mean(axis=0))) for lp in outer)
    assert centres == [(100, 120), (100, 120), (250, 100)]


def test_gray_frames_and_a_mm_homography():
    u, v = grid(W, H)
    cam = pixel_camera(W, H, mm_per_px=0.06)
    wl = WaterlineExtractor(cam).extract(draw(disc(u, v, 150, 110, 60), gray=True), 3.0)
    xy = wl.loops[0]
    r_mm = np.hypot(xy[:, 0] - 150 * 0.06, xy[:, 1] - (H - 110) * 0.06)
    assert np.sqrt(np.mean((r_mm - 60 * 0.06) ** 2)) < 0.1 * 0.06


def test_points_are_undistorted_not_the_frame():
    """A frame drawn through lens distortion measures true once its points are undistorted."""
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    dist = np.array([-0.25, 0.08, 0.001, -0.002, 0.0])
    u, v = grid(W, H)
    # for each distorted pixel, where is it in the ideal image?
    ideal = cv2.undistortPoints(np.column_stack([u.ravel(), v.ravel()]).reshape(-1, 1, 2), K, dist, P=K)
    iu, iv = ideal[:, 0, 0].reshape(H, W), ideal[:, 0, 1].reshape(H, W)
    frame = draw(disc(iu, iv, 150, 125, 80))  # ramp slightly off 1 px in distorted px: fine
    cam = pixel_camera(W, H)
    plain = WaterlineExtractor(cam).extract(frame, 0.0)
    cam.K, cam.dist = K, dist
    fixed = WaterlineExtractor(cam).extract(frame, 0.0)
    err_plain = np.abs(radial_error(plain.loops[0], 150, 125, 80))
    err_fixed = np.abs(radial_error(fixed.loops[0], 150, 125, 80))
    assert err_plain.max() > 1.0  # distortion is visible...
    assert np.sqrt(np.mean(err_fixed**2)) < 0.15  # ...and gone


def test_band_mode_follows_a_shrinking_disc_like_a_full_read():
    u, v = grid(W, H)
    banded, full = WaterlineExtractor(pixel_camera(W, H)), WaterlineExtractor(pixel_camera(W, H), band=False)
    modes = []
    for k, r in enumerate([80.0, 78.6, 77.1, 75.9, 70.0, 50.0]):
        f = draw(disc(u, v, 158.4, 121.7, r))
        a, b = banded.extract(f, 10 + k), full.extract(f, 10 + k)
        assert np.sqrt(np.mean(radial_error(a.loops[0], 158.4, 121.7, r) ** 2)) < 0.1
        np.testing.assert_allclose(signed_area(a.loops[0]), signed_area(b.loops[0]), rtol=1e-3)
        modes.append(banded.last_mode)
    assert modes[0] in ("coarse", "full") and modes[1:4] == ["band", "band", "band"]
    assert full.last_mode == "full"


def test_band_mode_sees_a_new_peak_come_out_far_from_the_band():
    u, v = grid(W, H)
    ex = WaterlineExtractor(pixel_camera(W, H))
    ex.extract(draw(disc(u, v, 90, 120, 50)), 20.0)
    wl = ex.extract(draw(np.maximum(disc(u, v, 90, 120, 51), disc(u, v, 250, 120, 25))), 19.0)
    assert len(wl.loops) == 2
    assert ex.last_mode == "band"


def test_an_island_appearing_while_the_liquid_rises_is_rejected():
    u, v = grid(W, H)
    ex = WaterlineExtractor(pixel_camera(W, H))
    ex.extract(draw(disc(u, v, 90, 120, 50)), 20.0)
    wl = ex.extract(draw(np.maximum(disc(u, v, 90, 120, 49), disc(u, v, 250, 120, 25))), 21.0)
    assert len(wl.loops) == 1
    assert any(e.kind == "rejected-island" for e in ex.events)


def test_salt_and_pepper_and_small_glare_specks_do_not_bend_or_split_the_line():
    u, v = grid(W, H)
    rng = np.random.default_rng(3)
    frame = draw(disc(u, v, 160, 120, 70))
    for _ in range(12):  # bright specks on the ink
        x, y = rng.integers(0, W), rng.integers(0, H)
        if np.hypot(x - 160, y - 120) > 80:
            cv2.circle(frame, (int(x), int(y)), 2, (255, 255, 255), -1)
    salt = rng.random((H, W)) < 0.01
    pepper = rng.random((H, W)) < 0.01
    frame[salt] = 255
    frame[pepper] = 0
    wl = WaterlineExtractor(pixel_camera(W, H)).extract(frame, 1.0)
    assert len(wl.loops) == 1
    err = radial_error(wl.loops[0], 160, 120, 70)
    assert np.sqrt(np.mean(err**2)) < 0.25
    assert len(wl.loops[0]) > 0.8 * 2 * np.pi * 70


def test_glare_touching_the_waterline_is_not_taken_as_part():
    u, v = grid(W, H)
    frame = draw(disc(u, v, 160, 120, 70))
    cv2.circle(frame, (160 + 73, 120), 4, (255, 255, 255), -1)  # a highlight on the ink at the edge
    wl = WaterlineExtractor(pixel_camera(W, H)).extract(frame, 1.0)
    err = radial_error(wl.loops[0], 160, 120, 70)
    assert np.abs(err).max() < 0.5


@pytest.mark.parametrize(
    "make, error",
    [
        (lambda: draw(np.full((H, W), -50.0)), NoPartError),
        (lambda: draw(np.full((H, W), 50.0)), AllPartError),
        (lambda: draw(disc(*grid(W, H), 160, 120, 50))[: H // 2], FrameError),
        (lambda: draw(disc(*grid(W + 8, H), 160, 120, 50)), FrameError),
        (lambda: np.zeros((H, W, 3), np.uint16), FrameError),
        (lambda: np.zeros((H, W, 5), np.uint8), FrameError),
        (lambda: "not an image", FrameError),
    ],
)
def test_bad_frames_give_clear_errors(make, error):
    ex = WaterlineExtractor(pixel_camera(W, H))
    with pytest.raises(error) as info:
        ex.extract(make(), 7.5)
    assert isinstance(info.value, ScanError) and isinstance(info.value, InkSliceError)
    assert "7.5" in info.value.where and info.value.problem


def test_truncated_file_with_zero_rows_is_refused():
    u, v = grid(W, H)
    frame = draw(disc(u, v, 160, 120, 50))
    frame[200:] = 0
    with pytest.raises(FrameError, match="truncated"):
        WaterlineExtractor(pixel_camera(W, H)).extract(frame, 1.0)


def test_an_all_ink_frame_mid_scan_is_an_error_and_the_next_frame_still_works():
    u, v = grid(W, H)
    ex = WaterlineExtractor(pixel_camera(W, H))
    ex.extract(draw(disc(u, v, 160, 120, 30)), 1.0)
    with pytest.raises(NoPartError):
        ex.extract(draw(np.full((H, W), -50.0)), 2.0)
    wl = ex.extract(draw(disc(u, v, 160, 120, 29)), 1.5)
    assert np.sqrt(np.mean(radial_error(wl.loops[0], 160, 120, 29) ** 2)) < 0.1


def test_all_ink_can_be_an_empty_waterline_for_the_top_of_a_scan():
    u, v = grid(W, H)
    ex = WaterlineExtractor(pixel_camera(W, H), no_part="empty")
    wl = ex.extract(draw(np.full((H, W), -50.0)), 30.0)
    assert wl.level_mm == 30.0 and wl.loops == []
    with pytest.raises(FrameError):  # bad frames still raise
        ex.extract(draw(np.full((H, W), -50.0))[:10], 29.0)
    assert len(ex.extract(draw(disc(u, v, 160, 120, 30)), 28.0).loops) == 1


def test_unknown_option_is_a_setting_error():
    with pytest.raises(InkSliceError, match="bogus"):
        WaterlineExtractor(pixel_camera(W, H), bogus=1)
