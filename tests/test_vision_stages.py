"""Each stage of the frame pipeline on its own, with known answers."""

import cv2
import numpy as np
import pytest
from test_vision_synth import INK, PART, draw, grid

from appliance.vision.band import TileGrid
from appliance.vision.frames import FrameError, best_channel, check_image, hue_split, otsu_split, towards_ink
from appliance.vision.subpixel import bumps, refine, refine_at, sample_q8


def test_otsu_split_finds_the_two_classes_and_ignores_clipped_glare():
    hist = np.zeros(256)
    hist[20] = 7000
    hist[200] = 3000
    hist[255] = 5000  # clipped glare: left out
    s = otsu_split(hist)
    assert 20 < s.threshold <= 200
    assert s.ink == pytest.approx(20) and s.part == pytest.approx(200)
    assert s.part_fraction == pytest.approx(0.3) and s.separability > 0.99
    t = towards_ink(s, 0.3)
    assert 20 < t.threshold <= min(s.threshold, np.ceil(20 + 0.3 * 180)) and t.otsu == s.threshold


def test_red_is_the_channel_for_dark_blue_ink_even_under_big_highlights():
    u, v = grid(200, 150)
    img = draw(10.0 - np.hypot(u - 100, v - 75))  # a small part
    glare = np.exp(-((u - 40) ** 2 + (v - 40) ** 2) / (2 * 30**2))[..., None] * np.array([150, 145, 142])
    img = np.clip(img + glare, 0, 255).astype(np.uint8)
    assert best_channel(img) == 2


def test_hue_cut_sits_between_blue_ink_and_the_grey_part():
    u, v = grid(200, 150)
    img = draw(30.0 - np.hypot(u - 100, v - 75))
    s = towards_ink(otsu_split(np.bincount(img[:, :, 2].ravel(), minlength=256)), 0.3)
    hue = hue_split(img, 2, s)
    d_ink, d_part = INK[0] - INK[2], max(PART[0] - PART[2], 0)
    assert hue.other == 0 and d_part < hue.cut < d_ink
    assert hue_split(img[:, :, 2], 2, s) is None  # gray frames: no colour test


def test_check_image_names_the_problem():
    ok = np.full((10, 20, 3), 30, np.uint8)
    check_image(ok, 20, 10)
    with pytest.raises(FrameError, match="truncated"):
        check_image(ok[:5], 20, 10)
    with pytest.raises(FrameError, match="8-bit"):
        check_image(ok.astype(np.float32), 20, 10)
    with pytest.raises(FrameError, match="20x10"):
        check_image(ok[:, :15], 20, 10)


def test_bilinear_q8_samples_are_exact_on_a_ramp():
    img = np.tile(np.arange(0, 250, 10, dtype=np.uint8), (5, 1))  # 10 grey levels per pixel
    x = np.array([[0.0, 0.5, 3.25, 7.75]], np.float32)
    y = np.full_like(x, 2.0)
    np.testing.assert_allclose(sample_q8(img, x, y) / 256.0, 10 * x, atol=0.05)


@pytest.mark.parametrize("angle", [0.0, 13.0, 45.0, 71.0])
def test_straight_edge_found_to_a_few_hundredths_of_a_pixel(angle):
    u, v = grid(120, 100)
    a = np.radians(angle)
    n = np.array([np.cos(a), np.sin(a)])
    c = 60.3 * n[0] + 50.0 * n[1] + 0.37  # edge line: n . p = c
    # a 2-px ramp (as the renderer draws): both pixels astride the edge are on it
    img = cv2.medianBlur(draw((c - (u * n[0] + v * n[1])) / 2, gray=True), 3)
    binary = (img >= 100).astype(np.uint8) * 255
    contours, _ = cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    chain = max(contours, key=len).reshape(-1, 2)
    pts, idx = refine(img, chain, threshold=100)
    inner = (pts[:, 0] > 8) & (pts[:, 0] < 112) & (pts[:, 1] > 8) & (pts[:, 1] < 92)  # off the frame's edge
    dist = pts[inner] @ n - c
    assert inner.sum() > 50
    assert np.sqrt(np.mean(dist**2)) < 0.05


def test_a_sliver_narrower_than_the_profile_is_placed_where_it_crosses_the_level_given():
    """A strip 3 px wide, blurred to a peak of 60 over ink at 20: a 9-px profile from its edge
    runs from ink to ink, so it has no half-way point; it crosses the level given (40) where
    the blurred strip does."""
    u, v = grid(120, 60)
    strip = ((v >= 28.5) & (v < 31.5)).astype(np.float32)  # rows 29-31 are the sliver
    blurred = cv2.GaussianBlur(strip, (0, 0), 1.2)
    img = np.clip(np.rint(20 + 40 * blurred / blurred.max()), 0, 255).astype(np.uint8)
    binary = (img >= 40).astype(np.uint8) * 255
    contours, _ = cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    chain = max(contours, key=len).reshape(-1, 2)
    mid = (chain[:, 0] > 10) & (chain[:, 0] < 110)
    assert len(refine(img, chain, threshold=40, min_contrast=12)[1]) < mid.sum() / 4
    pts, idx = refine_at(img, chain, np.arange(len(chain)), 40.0)
    inner = (pts[:, 0] > 10) & (pts[:, 0] < 110)
    assert inner.sum() > 150  # both sides, nearly every pixel
    # where the blurred strip itself passes 40, along each column
    col = img[:, 60].astype(float)
    above = np.nonzero(col >= 40)[0]
    lo, hi = above[0], above[-1]
    top = lo - 1 + (40 - col[lo - 1]) / (col[lo] - col[lo - 1])
    bottom = hi + (col[hi] - 40) / (col[hi] - col[hi + 1])
    side = np.where(pts[inner, 1] < 30, top, bottom)
    assert np.abs(pts[inner, 1] - side).max() < 0.1


def test_a_speck_on_the_line_is_a_bump_and_a_corner_is_not():
    t = np.linspace(0, 2 * np.pi, 600, endpoint=False)
    circle = np.column_stack([95 * np.cos(t), 95 * np.sin(t)])
    bumped = circle.copy()
    bumped[300:306] *= (95 + np.array([1.5, 3, 4, 4, 3, 1.5]))[:, None] / 95
    flagged = np.nonzero(bumps(bumped))[0]
    assert set(range(301, 305)) <= set(flagged) and flagged.min() >= 296 and flagged.max() <= 309
    side = np.arange(0, 100, 1.0)
    square = np.vstack(
        [
            np.column_stack([side, np.zeros(100)]),
            np.column_stack([np.full(100, 100.0), side]),
            np.column_stack([100 - side, np.full(100, 100.0)]),
            np.column_stack([np.zeros(100), 100 - side]),
        ]
    )
    assert not bumps(square).any()


def test_band_tiles_gathered_filtered_and_scattered_match_the_whole_frame():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (100, 130), dtype=np.uint8)
    g = TileGrid((0, 0, 130, 100), 16)
    ty, tx = np.array([0, 2, 3, 5]), np.array([1, 4, 0, 7])
    out = np.zeros_like(img)
    g.scatter(cv2.medianBlur(g.gather(img, ty, tx), 3), out, ty, tx)
    whole = cv2.medianBlur(img, 3)
    for y, x in zip(ty, tx):
        sl = np.s_[1 + 16 * y : 17 + 16 * y, 1 + 16 * x : 17 + 16 * x]
        np.testing.assert_array_equal(out[sl], whole[sl])
    p = np.array([[40.0, 40.0]])  # tiles start at 1 + 16 k: this is in tile (2, 2)
    mask = np.zeros(g.shape, bool)
    g.mark(mask, p, 5, thin=False)  # [35, 45] stays in tile 2
    assert mask.sum() == 1 and mask[2, 2]
    g.mark(mask, p, 10, thin=False)  # [30, 50] reaches tiles 1..3
    assert mask.sum() == 9 and mask[1:4, 1:4].all()
    assert g.all_marked(mask, p, 10) and not g.all_marked(mask, p, 30)
