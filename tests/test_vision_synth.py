"""Small synthetic frames with known waterlines, for the vision tests.

A frame is drawn from a signed distance d(u, v) in pixels (> 0 on the part):
each pixel's part coverage is a linear ramp clip(0.5 + d), so the 50 % grey
crossing lies exactly on d = 0. Colours: dark-blue ink, a light grey part.
"""

import numpy as np

from appliance.vision.camera import CameraModel

INK = np.array([90.0, 30.0, 12.0])  # BGR: dark blue
PART = np.array([200.0, 205.0, 210.0])


def grid(w, h):
    return np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))


def draw(d, ink=INK, part=PART, gray=False):
    cover = np.clip(0.5 + d, 0.0, 1.0)[..., None]
    img = ink + cover * (part - ink)
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return img[:, :, 2].copy() if gray else img


def disc(u, v, cx, cy, r):
    return r - np.hypot(u - cx, v - cy)


def ring(u, v, cx, cy, r_in, r_out):
    rr = np.hypot(u - cx, v - cy)
    return np.minimum(r_out - rr, rr - r_in)


def pixel_camera(w, h, mm_per_px=1.0):
    """(u, v) -> (x, y) = (u, h - v) * scale: y up, as the object frame wants."""
    H = np.array([[mm_per_px, 0, 0], [0, -mm_per_px, h * mm_per_px], [0, 0, 1]], float)
    return CameraModel(w, h, H)


def to_pixels(xy, h, mm_per_px=1.0):
    return np.column_stack([xy[:, 0] / mm_per_px, h - xy[:, 1] / mm_per_px])


def test_ramp_crosses_half_way_on_the_boundary():
    u, v = grid(40, 30)
    img = draw(disc(u, v, 20, 15, 8.5), gray=True)
    mid = 0.5 * (INK[2] + PART[2])
    # pixel centres 0.5 px inside / outside sit at 100 % / 0 % of the way up
    assert img[15, 20 + 8] > mid > img[15, 20 + 9]
    assert img[15, 0] == round(INK[2]) and img[15, 20] == round(PART[2])
