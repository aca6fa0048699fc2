"""What degrades the virtual bench's ideal image, and the presets that bundle it.

The renderer (render.py) computes the exact image of part and ink; everything
a real bench adds on top lives here, so the geometry and the nuisances can be
read apart: glare and dust floating on the ink (drawn afresh per frame, or,
for the harsh bench, along paths laid out once per scan that drift with the
level), stage wobble (a shifted pixel map), and the camera itself: lamp
flicker, vignetting, blur, sensor noise, stuck pixels and JPEG. The physical
effects (displacement, meniscus, ripples) are switched here too, but modelled
in physics.py and waterline.py.

Everything random is drawn from the `rng` passed in, so a frame stays a pure
function of (surface, level, rig, effects, rng state).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np

from ..errors import SettingError
from . import physics
from .rig import PixelMap, Rig


@dataclass(frozen=True)
class Effects:
    """What degrades the ideal image. All off = the clean, exact image."""

    blur_sigma_px: float = 0.0  # Gaussian optical blur
    noise_sigma: float = 0.0  # sensor noise, DN (of 255)
    salt_pepper: float = 0.0  # fraction of pixels stuck black or white
    glare_spots: int = 0  # specular highlights on the liquid
    glare_strength: float = 150.0  # DN added at a highlight's centre
    vignetting: float = 0.0  # fractional fall-off of light at the image corners
    lens_distortion: bool = False  # the frames carry the rig's lens distortion
    dust_specks: int = 0  # dust specks and small bubbles floating on the ink
    displacement: bool = False  # the ink level drops as the part emerges
    meniscus: bool = False  # ink climbs the part at the contact line
    capillary_length_mm: float = physics.CAPILLARY_LENGTH_MM
    contact_angle_deg: float = 0.0
    contact_line_curvature: bool = False  # the second meniscus model (physics.meniscus_rise_curved)
    ripple_mm: float = 0.0  # amplitude of the free surface's oscillation just after a move
    ripple_age_s: float = 0.0  # time since the move stopped (VirtualCamera sets it)
    ripple_decay_s: float = 0.6
    trapped_ink: bool = False  # pockets in the part's top stay full once their rim is out (pockets.py)
    base_shows: bool = False  # the base top, once at or above the ink, is drawn (lit, like the part)
    base_half_mm: float = 60.0  # half the side of the square base, centred under the parts
    # A scan's worth of nuisances that move (the harsh bench). Off, glare and dust are drawn
    # afresh in every frame; on, they follow paths laid out once (seeded by drift_seed) that
    # drift as the level changes, jitter from frame to frame (the frame's rng), and each glare
    # blob flickers and now and then vanishes: a bright thing that comes and goes.
    drifting: bool = False
    drift_seed: int = 0
    flicker: float = 0.0  # the lamp's brightness per frame: x (1 + u * flicker), u in [-1, 1]
    jpeg_quality: int = 0  # the frame passes through JPEG at this quality (0: it does not)
    wobble_mm: float = 0.0  # lateral stage play: each frame sees the part shifted up to this far

    def to_json(self):
        return asdict(self)


_REALISTIC = Effects(
    blur_sigma_px=0.8,
    noise_sigma=2.5,
    salt_pepper=2e-5,
    glare_spots=3,
    vignetting=0.25,
    lens_distortion=True,
    dust_specks=30,
)
_PHYSICS = replace(_REALISTIC, displacement=True, meniscus=True)

PRESETS = {
    "clean": Effects(),
    "optics": Effects(blur_sigma_px=0.7, vignetting=0.25, lens_distortion=True),
    "realistic": _REALISTIC,
    "physics": _PHYSICS,
    # a second ink, another meniscus model: wets at 35 deg (a depression on flatter faces),
    # the contact line's own curvature raising the meniscus in pits and lowering it on ridges
    "physics2": replace(
        _PHYSICS, capillary_length_mm=2.3, contact_angle_deg=35.0, contact_line_curvature=True
    ),
    # Everything at once, moving: glare that drifts, jitters and flickers from frame to frame,
    # drifting dust and bubbles, salt and pepper, JPEG q85, 1.5 % lamp flicker, 0.05 mm of
    # stage wobble no calibration knows about, a rippling surface, and a meniscus that is not
    # the first model's: another capillary length and the contact line's own curvature. Its
    # contact angle stays 0: a depression on flat faces (physics2) is the meniscus model's
    # open question (benches/meniscus.py), not the images'.
    "harsh": Effects(
        blur_sigma_px=1.3,
        noise_sigma=6.0,
        salt_pepper=3e-4,
        glare_spots=6,
        glare_strength=200.0,
        vignetting=0.4,
        lens_distortion=True,
        dust_specks=120,
        displacement=True,
        meniscus=True,
        capillary_length_mm=2.5,
        contact_line_curvature=True,
        ripple_mm=0.05,
        ripple_age_s=0.5,
        drifting=True,
        drift_seed=18,
        flicker=0.015,
        jpeg_quality=85,
        wobble_mm=0.05,
    ),
}


def effects_preset(name: str) -> Effects:
    try:
        return PRESETS[name]
    except KeyError:
        raise SettingError(
            "effects", f"unknown effects preset {name!r}; known: {', '.join(PRESETS)}"
        ) from None


# -- glare and dust on the ink ------------------------------------------------------


def _fresh_glare(W, H, effects, rng, level_mm):
    """Glare drawn afresh for this frame: (cx, cy, sx, sy, peak) per blob."""
    for _ in range(effects.glare_spots):
        cx, cy = rng.uniform(0, W), rng.uniform(0, H)
        sx, sy = rng.uniform(15, 70), rng.uniform(15, 70)
        yield cx, cy, sx, sy, effects.glare_strength * rng.uniform(0.5, 1.0)


def _fresh_dust(W, H, effects, rng, level_mm):
    """Dust and bubbles drawn afresh for this frame: (cx, cy, radius, is_bubble, shade)."""
    for _ in range(effects.dust_specks):
        cx, cy = rng.uniform(0, W), rng.uniform(0, H)
        rad = rng.uniform(0.8, 3.5)
        bubble = rng.uniform() < 0.4
        yield cx, cy, rad, bubble, (1.0 if bubble else rng.uniform(0.6, 1.4))


DRIFT_JITTER_PX = 6.0  # frame-to-frame wander of a drifting glare blob (ripples, the lamp)


def _layout(effects, n, speed_px_per_mm):
    """Where drifting things start and how fast they move, the same for every frame of a scan."""
    lay = np.random.default_rng([effects.drift_seed, n])
    start = lay.uniform(0.0, 1.0, (n, 2))
    angle = lay.uniform(0.0, 2 * np.pi, n)
    speed = lay.uniform(*speed_px_per_mm, n)
    return start, speed[:, None] * np.column_stack([np.cos(angle), np.sin(angle)]), lay


GLARE_WINDOW = 0.6  # drifting glare wanders over the middle 60 % of the frame, where parts are


def _drifting_glare(W, H, effects, rng, level_mm):
    start, vel, lay = _layout(effects, effects.glare_spots, (8.0, 40.0))
    size = lay.uniform(15, 70, (effects.glare_spots, 2))
    w, h = GLARE_WINDOW * W, GLARE_WINDOW * H
    for (x0, y0), (vx, vy), (sx, sy) in zip(start, vel, size):
        jx, jy = rng.normal(0.0, DRIFT_JITTER_PX, 2)
        grow = rng.uniform(0.8, 1.2)
        peak = effects.glare_strength * rng.uniform(0.4, 1.0)
        if rng.uniform() < 0.35:  # the highlight is gone in this frame
            continue
        yield (
            (W - w) / 2 + (x0 * w + vx * level_mm + jx) % w,
            (H - h) / 2 + (y0 * h + vy * level_mm + jy) % h,
            sx * grow,
            sy * grow,
            peak,
        )


def _drifting_dust(W, H, effects, rng, level_mm):
    start, vel, lay = _layout(effects, effects.dust_specks, (3.0, 15.0))
    rad = lay.uniform(0.8, 3.5, effects.dust_specks)
    bubble = lay.uniform(size=effects.dust_specks) < 0.4
    shade = lay.uniform(0.6, 1.4, effects.dust_specks)
    for i in range(effects.dust_specks):
        jx, jy = rng.normal(0.0, 1.0, 2)
        yield (
            (start[i, 0] * W + vel[i, 0] * level_mm + jx) % W,
            (start[i, 1] * H + vel[i, 1] * level_mm + jy) % H,
            rad[i],
            bubble[i],
            shade[i],
        )


def _window(cx, cy, r, W, H):
    """The frame's pixels within r of (cx, cy): ((ya, yb, xa, xb), u, v), u and v the
    columns' and rows' offsets from the centre; None when none is in the frame."""
    xa, xb = int(max(0, cx - r)), int(min(W, cx + r + 1))
    ya, yb = int(max(0, cy - r)), int(min(H, cy + r + 1))
    if xa >= xb or ya >= yb:
        return None
    u = np.arange(xa, xb, dtype=np.float32) - cx
    v = np.arange(ya, yb, dtype=np.float32) - cy
    return (ya, yb, xa, xb), u, v


def liquid_layer(rig, effects, level_mm, rng):
    """The ink as the camera sees it: flat dark blue, plus glare and dust on it."""
    H, W = rig.height, rig.width
    ink = np.empty((H, W, 3), np.float32)
    ink[:] = np.asarray(rig.ink_bgr, np.float32)
    glare = _drifting_glare if effects.drifting else _fresh_glare
    for cx, cy, sx, sy, peak in glare(W, H, effects, rng, level_mm):
        # a specular highlight: a soft, slightly elongated blob of the lamp's colour
        win = _window(cx, cy, int(3.5 * max(sx, sy)), W, H)
        if win is None:
            continue
        (ya, yb, xa, xb), u, v = win
        blob = peak * np.exp(-0.5 * ((v[:, None] / sy) ** 2 + (u[None, :] / sx) ** 2))
        ink[ya:yb, xa:xb] += blob[..., None] * np.array([1.0, 0.97, 0.95], np.float32)
    dust = _drifting_dust if effects.drifting else _fresh_dust
    for cx, cy, rad, bubble, shade in dust(W, H, effects, rng, level_mm):
        win = _window(cx, cy, int(rad + 3), W, H)
        if win is None:
            continue
        (ya, yb, xa, xb), u, v = win
        d = np.sqrt(v[:, None] ** 2 + u[None, :] ** 2)
        cover = np.clip(rad + 0.5 - d, 0, 1)[..., None]
        if bubble:
            # a bubble: bright rim around a dark centre
            rim = np.clip(1.0 - np.abs(d - rad * 0.8) / max(rad * 0.35, 0.6), 0, 1)[..., None]
            colour = np.asarray(rig.ink_bgr, np.float32) * 0.6 + 140.0 * rim
        else:
            # dust: grey-brown speck
            colour = np.array([90, 100, 110], np.float32) * shade
        patch = ink[ya:yb, xa:xb]
        patch[:] = patch * (1 - cover) + colour * cover
    return ink


def wobbled(pm: PixelMap, effects: Effects, rng) -> PixelMap:
    """The pixel map of a frame whose part sits up to wobble_mm off where the stage says."""
    if effects.wobble_mm <= 0:
        return pm
    r = effects.wobble_mm * math.sqrt(rng.uniform())
    a = rng.uniform(0.0, 2 * math.pi)
    return replace(pm, x0=pm.x0 - np.float32(r * math.cos(a)), y0=pm.y0 - np.float32(r * math.sin(a)))


def camera_effects(img, rig: Rig, effects: Effects, pm: PixelMap, rng) -> np.ndarray:
    """What the lens and sensor do to the light: vignetting, blur, noise, stuck pixels.
    `img` is float32 BGR (0..255), modified in place; returns 8-bit BGR."""
    if effects.flicker > 0:
        img *= np.float32(1.0 + effects.flicker * rng.uniform(-1.0, 1.0))
    if effects.vignetting > 0:
        img *= (1.0 - effects.vignetting * pm.vignette_r2)[..., None]
    if effects.blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), effects.blur_sigma_px)
    if effects.noise_sigma > 0:
        # OpenCV's generator is ~2x faster than numpy's on 9.4 M samples; seeding it
        # from rng keeps the frame a function of the rng's state (its state is per thread)
        cv2.setRNGSeed(int(rng.integers(1, 2**31)))
        noise = np.empty_like(img)
        cv2.randn(noise, 0.0, float(effects.noise_sigma))
        cv2.add(img, noise, dst=img)
    if effects.salt_pepper > 0:
        n = int(rng.binomial(img.shape[0] * img.shape[1], effects.salt_pepper))
        if n:
            r = rng.integers(0, img.shape[0], n)
            c = rng.integers(0, img.shape[1], n)
            img[r, c] = np.where(rng.uniform(size=n) < 0.5, 0.0, 255.0)[:, None]
    # round and saturate to 8 bits (convertScaleAbs would fold negatives up: clamp first)
    cv2.max(img, 0.0, dst=img)
    out = cv2.convertScaleAbs(img)
    if effects.jpeg_quality:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(effects.jpeg_quality)])
        out = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    return out
