"""The virtual bench's renderer: the waterline where the analytic level curve says,
perspective as a pinhole camera says, and the effects deterministic."""

import cv2
import numpy as np
import pytest

from appliance.sim import surfaces as S
from appliance.sim.render import PRESETS, Effects, part_layer_roi, render_frame, surface_grid, trace
from appliance.sim.rig import Rig, pixel_map

RIG = Rig()


def _crossings(gray, axis, reach=6, min_cos=0.5):
    """50 % crossings between ink and part along rows (axis=1) or columns (axis=0).

    The mid level is taken locally from the pixels 4 px either side, so the
    part's shading does not bias it; both pixels straddling the crossing must
    lie strictly inside the ramp (no clipped neighbour).
    """
    g = gray if axis == 1 else gray.T
    pts = []
    ink = float(np.median(g[:, :20]))
    for r in range(0, g.shape[0], 3):
        row = g[r]
        brighter = row > ink + 20
        edges = np.nonzero(brighter[1:] != brighter[:-1])[0]
        for j in edges:
            if j < reach + 2 or j > row.size - reach - 3:
                continue
            lo, hi = sorted((row[j - reach], row[j + reach + 1]))
            if hi - lo < 60:
                continue
            mid = 0.5 * (lo + hi)
            for i in range(j - 2, j + 3):
                a, b = row[i], row[i + 1]
                if (a - mid) * (b - mid) <= 0 and a != b:
                    if min(a, b) <= lo + 1 or max(a, b) >= hi - 1:
                        break  # a clipped neighbour: not a clean ramp
                    if abs(b - a) < 0.5 * min_cos * (hi - lo):
                        break  # grazing: too far off the normal
                    t = (mid - a) / (b - a)
                    pts.append((i + t, r) if axis == 1 else (r, i + t))
                    break
    return np.array(pts, float).reshape(-1, 2)


def _gray(img):
    return img.astype(np.float64).mean(axis=2)


def _to_plane(rig, uv, undistort=False):
    if undistort:
        uv = cv2.undistortPoints(
            uv.reshape(-1, 1, 2),
            rig.K(),
            rig.dist_coeffs(),
            None,
            None,
            rig.K(),
            (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14),
        ).reshape(-1, 2)
    Hm = rig.homography()
    p = np.column_stack([uv, np.ones(len(uv))]) @ Hm.T
    return p[:, :2] / p[:, 2:]


def _waterline_errors(surface, level, effects, undistort=False, keep=None):
    img = render_frame(surface, level, RIG, effects)
    gray = _gray(img)
    uv = np.vstack([_crossings(gray, 1), _crossings(gray, 0)])
    xy = _to_plane(RIG, uv, undistort)
    if keep is not None:
        m = keep(xy)
        uv, xy = uv[m], xy[m]
    sdf = surface.level_sdf(xy[:, 0], xy[:, 1], level)
    pix = float(np.median(pixel_map(RIG, False).pix))
    return np.abs(sdf), np.abs(sdf) / pix, xy


def test_homography_orientation_is_a_top_view():
    Hm = RIG.homography()

    def xy(u, v):
        p = Hm @ [u, v, 1.0]
        return p[:2] / p[2]

    c = xy(1024, 768)
    assert xy(1124, 768)[0] > c[0] + 7  # u right -> x right
    assert xy(1024, 668)[1] > c[1] + 7  # v up the image -> y away from the viewer
    assert 0.07 <= np.linalg.norm(xy(1025, 768) - c) <= 0.08
    # not a pure scale: the stand is tilted
    assert abs(Hm[2, 0]) + abs(Hm[2, 1]) > 1e-7
    # covers a 100 x 100 mm part with margin
    for u, v in [(0, 0), (2047, 0), (0, 1535), (2047, 1535)]:
        x, y = xy(u, v)
        assert (x < -5 or x > 105) and (y < -5 or y > 105)


def test_camera_model_round_trip():
    cm = RIG.camera_model()
    P = np.array([[10.0, 20.0, 0.0], [70.0, 90.0, 0.0]])
    uv = RIG.project(P)
    p = np.column_stack([uv, np.ones(2)]) @ cm.homography.T
    assert np.allclose(p[:, :2] / p[:, 2:], P[:, :2], atol=1e-9)
    assert cm.height_mm == RIG.height_mm and cm.dist.shape == (5,)
    # distorted projection agrees with OpenCV's
    R = RIG.rotation()
    rvec, _ = cv2.Rodrigues(R)
    uvd, _ = cv2.projectPoints(P, rvec, -R @ RIG.centre, RIG.K(), RIG.dist_coeffs())
    assert np.allclose(uvd.reshape(-1, 2), RIG.project(P, distorted=True), atol=1e-9)


def _on_the_top(surface, margin=0.5):
    """Points well inside the footprint: there the waterline runs on the sculptured
    top. At the footprint's edge it runs on a wall, which faces away from the camera
    and is hidden by the rim (see the ring test)."""

    def keep(xy):
        fp = np.max([t.footprint(xy[:, 0], xy[:, 1]) for t in surface.tiers], axis=0)
        return fp > margin

    return keep


@pytest.mark.parametrize(
    "name,level", [("sample1", 20.0), ("twin-peaks", 14.0), ("sample3", 40.0), ("sample2", 30.0)]
)
def test_waterline_is_the_analytic_level_curve(name, level):
    err_mm, err_px, _ = _waterline_errors(S.get(name), level, Effects(), keep=_on_the_top(S.get(name)))
    assert err_mm.size > 300
    print(
        f"{name} L={level}: {err_mm.size} crossings, max {err_mm.max():.5f} mm "
        f"({err_px.max():.4f} px), rms {np.sqrt(np.mean(err_mm**2)):.5f} mm"
    )
    assert err_mm.max() < 0.01
    assert err_px.max() < 0.1


def test_waterline_through_lens_distortion():
    """Frames carry the lens distortion; undistorting the crossings recovers the curve."""
    err_mm, err_px, _ = _waterline_errors(
        S.get("sample1"), 20.0, Effects(lens_distortion=True), undistort=True
    )
    assert err_mm.size > 500
    print(f"distorted: max {err_mm.max():.5f} mm ({err_px.max():.4f} px)")
    assert err_mm.max() < 0.01 and err_px.max() < 0.1
    # and without undistorting it would be visibly wrong at the part's edge
    img = render_frame(S.get("sample1"), 20.0, RIG, Effects(lens_distortion=True))
    uv = _crossings(_gray(img), 1)
    xy = _to_plane(RIG, uv, undistort=False)
    assert np.abs(S.get("sample1").level_sdf(xy[:, 0], xy[:, 1], 20.0)).max() > 0.02


def test_visible_wall_and_hidden_wall_of_the_ring():
    """Level 1 on the ring (top 8 mm at both walls), camera 8 mm left of the hole's
    centre. The hole's far wall faces the camera: its waterline is seen, with a
    band of lit-from-the-side wall above it. The outer wall faces away: the rim
    7 mm above the ink hides the waterline, and the edge seen there is the rim,
    moved outwards by perspective exactly as the pinhole says."""
    ring, level = S.get("ring"), 1.0
    rig = Rig(camera_x_mm=42.0)
    img = render_frame(ring, level, rig, Effects())
    gray = _gray(img)
    # the wall band is only ~7 px wide: take the plateaus 3-4 px out, rows near the normal
    uv = np.vstack([_crossings(gray, 1, reach=3, min_cos=0.8), _crossings(gray, 0, reach=3, min_cos=0.8)])
    xy = _to_plane(rig, uv)
    r = np.hypot(xy[:, 0] - 50, xy[:, 1] - 50)
    inner = (r < 30) & (xy[:, 0] > 58)
    outer = r > 40
    assert inner.sum() > 40 and outer.sum() > 500
    sdf = np.abs(ring.level_sdf(xy[inner, 0], xy[inner, 1], level))
    pix = float(np.median(pixel_map(rig, False).pix))
    print(f"visible wall: {inner.sum()} crossings, max {sdf.max():.5f} mm")
    assert sdf.max() < 0.01
    # outer edge: the rim of the top (r = 45, z = 8), i.e. 7 mm above the liquid
    o = xy[outer]
    C = rig.centre
    rim = o + (C[:2] - o) * (8.0 - level) / C[2]
    r_rim = np.hypot(rim[:, 0] - 50, rim[:, 1] - 50)
    print(f"rim silhouette: {o.shape[0]} crossings, max {np.abs(r_rim - 45).max():.5f} mm")
    assert np.abs(r_rim - 45).max() < 0.01  # anti-aliased: as exact as the waterline
    r_seen = np.hypot(o[:, 0] - 50, o[:, 1] - 50)
    assert np.median(r_seen - 45) > 8 * pix  # the waterline itself is hidden


def test_a_low_rim_near_the_axis_hides_the_waterline():
    """The steps' boss (top ~21.7 mm at its y = 55 edge) with the ink at 15 mm: that
    wall faces away from the camera, which is only ~6 mm from it, so the rim 6.7 mm
    above the ink sits just 1.6 px outside the hidden waterline. The edge seen must
    be the rim's, not the waterline's."""
    steps, level = S.get("steps"), 15.0
    boss = steps.tiers[1]
    img = render_frame(steps, level, RIG, Effects())
    gray = _gray(img)
    uv = np.vstack([_crossings(gray, 1), _crossings(gray, 0)])
    xy = _to_plane(RIG, uv)
    near = (xy[:, 0] > 32) & (xy[:, 0] < 58) & (np.abs(xy[:, 1] - 55) < 1.5)
    assert near.sum() > 50
    P0 = xy[near]
    C = RIG.centre
    z = np.full(len(P0), level)
    for _ in range(30):  # the ray meets the boss's top: z = top(P(z))
        P = P0 + (C[:2] - P0) * ((z - level) / C[2])[:, None]
        z = boss.top(P[:, 0], P[:, 1])
    P = P0 + (C[:2] - P0) * ((z - level) / C[2])[:, None]
    err = np.abs(boss.footprint(P[:, 0], P[:, 1]))
    pix = float(np.median(pixel_map(RIG, False).pix))
    print(
        f"low rim near the axis: {near.sum()} crossings, max {err.max():.5f} mm from the rim; "
        f"waterline {np.median(P0[:, 1] - 55) / pix:.2f} px inside"
    )
    assert err.max() < 0.01
    assert np.median(P0[:, 1] - 55) > 1.2 * pix


def _drawn_and_rays(part, level):
    """The part layer's alpha over its pixel rectangle, and each pixel's ray there:
    (x0, y0, kx, ky), where it meets the liquid and its slope per mm of height."""
    pm = pixel_map(RIG, False)
    (r0, r1, c0, c1), alpha, _ = part_layer_roi(part, level, RIG, Effects(), pm)
    rays = tuple(a.reshape(RIG.height, RIG.width)[r0:r1, c0:c1] for a in (pm.x0, pm.y0, pm.kx, pm.ky))
    return alpha, rays


def _deepest(part, level, rays, rows, cols, steps):
    """How deep (mm) each pixel's ray gets into the part, marched at `steps` heights from
    the liquid to above the part's top: >= 0 where it meets it."""
    x0, y0, kx, ky = rays
    zs = np.linspace(level, surface_grid(part).z_max + 0.2, steps)[1:]
    out = np.empty(rows.size)
    for a in range(0, rows.size, 500):
        r, c = rows[a : a + 500], cols[a : a + 500]
        px = x0[r, c][:, None] + kx[r, c][:, None] * (zs - level)
        py = y0[r, c][:, None] + ky[r, c][:, None] * (zs - level)
        out[a : a + 500] = (part.height(px, py) - zs).max(axis=1)
    return out


def test_a_battered_wall_facing_away_is_drawn_to_its_rims_silhouette():
    """The stepped block's 85 deg outer wall at y = 86 leans away from the camera by a hair
    more than the rays there: the rim hides it. Down a column of pixels across it, at
    level 7.44, the part is drawn exactly where a pixel's ray meets the part on its way down
    (it was drawn 2 px further out, where Newton's search for the ray's crossing, grazing
    the wall, ended off the top but inside the footprint)."""
    block, level = S.get("stepped-block"), 7.44
    alpha, rays = _drawn_and_rays(block, level)
    x0, y0 = rays[0], rays[1]
    col = int(np.argmin(np.abs(x0[0] - 50.0)))
    rows = np.flatnonzero((y0[:, col] > 84.5) & (y0[:, col] < 87.0))
    met = list(_deepest(block, level, rays, rows, np.full(rows.size, col), 6000) >= 0)
    drawn = list(alpha[rows, col] >= 0.5)
    assert 10 < sum(met) < len(rows) - 10  # the column crosses the rim
    assert drawn == met


def test_every_silhouette_pixel_of_the_stepped_block_is_drawn_as_its_ray_meets_the_part():
    """All round the stepped block at level 6.44, in the 3 px band about its drawn outline,
    a pixel is drawn (alpha >= 0.5) when its ray, marched down from above, meets the part;
    where the two disagree, the ray passes within CLIP_MM of the part's surface (a rim's
    rounded corner, which the renderer's 0.1 mm grid holds to about that, or a waterline's
    ramp). Newton's search, started at the liquid, used to stop where a ray grazing a
    battered wall comes out of it, under the top the camera sees: a 2 px strip along the
    y = 86 rim was drawn as ink over rays 1.2 mm deep in the part."""
    block, level, clip_mm = S.get("stepped-block"), 6.44, 0.1
    alpha, rays = _drawn_and_rays(block, level)
    drawn = alpha >= 0.5
    band = cv2.dilate(drawn.view(np.uint8), np.ones((7, 7), np.uint8)) > cv2.erode(
        drawn.view(np.uint8), np.ones((7, 7), np.uint8)
    )
    rr, cc = np.nonzero(band)
    deepest = _deepest(block, level, rays, rr, cc, 3000)
    assert rr.size > 20000  # the whole outline, both tiers
    wrong = (deepest >= 0) != drawn[rr, cc]
    assert np.abs(deepest[wrong]).max() < clip_mm


def test_a_point_on_top_of_a_tall_part_appears_where_the_pinhole_says():
    """Trace the pixels where the pinhole projects points of the sphere's cap: the ray
    must meet the part exactly there (to a micrometre), 30 mm above the base."""
    sph, level = S.get("sphere"), 2.0
    grid = surface_grid(sph)
    pts = np.array([[50, 50], [40, 55], [62, 45], [55, 68], [33, 40]], float)
    Q = np.column_stack([pts, sph.height(pts[:, 0], pts[:, 1])])
    uv = RIG.project_object(Q, level)
    P0 = RIG.pixels_to_plane(uv)
    C = RIG.centre
    kx, ky = (C[0] - P0[:, 0]) / C[2], (C[1] - P0[:, 1]) / C[2]
    hit, z, tier, wall = trace(grid, P0[:, 0], P0[:, 1], kx.astype(np.float32), ky.astype(np.float32), level)
    assert hit.all() and not wall.any()
    assert np.abs(z - Q[:, 2]).max() < 2e-3
    xh = P0[:, 0] + kx * (z - level)
    yh = P0[:, 1] + ky * (z - level)
    assert np.hypot(xh - Q[:, 0], yh - Q[:, 1]).max() < 1e-3
    # and in the image: the apex region is bright part where the ink would be
    # without perspective the cap's edge would appear at r = 29 mm; it appears larger
    img = render_frame(sph, level, RIG, Effects())
    row = _gray(img)[int(round(RIG.project_object([[50, 50, 0]], level)[0, 1]))]
    assert row.max() > 150


def test_effects_are_deterministic_and_do_something():
    s = S.get("cone")
    a = render_frame(s, 10.0, RIG, PRESETS["realistic"], np.random.default_rng(3))
    b = render_frame(s, 10.0, RIG, PRESETS["realistic"], np.random.default_rng(3))
    c = render_frame(s, 10.0, RIG, PRESETS["realistic"], np.random.default_rng(4))
    clean = render_frame(s, 10.0, RIG, Effects())
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    d = np.abs(a.astype(int) - clean.astype(int))
    assert d.mean() > 1.0
    # glare brightens the ink somewhere far more than noise could
    ink_region = clean[..., 0] < 80
    assert (a[..., 0][ink_region].astype(int) - clean[..., 0][ink_region] > 40).sum() > 500


def _lit(effects, level, i):
    """Where glare (much brighter than the ink) and anything else (not the ink's colour) lie in frame i."""
    from appliance.sim.effects import liquid_layer

    ink = liquid_layer(RIG, effects, level, np.random.default_rng([1, i]))
    plain = np.asarray(RIG.ink_bgr, np.float32)
    diff = np.abs(ink - plain).max(axis=2)
    return diff > 40, diff > 5


def test_harsh_glare_and_dust_move_and_flicker_from_frame_to_frame():
    from dataclasses import replace

    harsh = PRESETS["harsh"]
    glare = replace(harsh, dust_specks=0)
    g1, _ = _lit(glare, 20.0, 1)
    g1_again, _ = _lit(glare, 20.0, 1)
    g2, _ = _lit(glare, 19.0, 2)
    assert np.array_equal(g1, g1_again)  # a pure function of level and frame seed
    assert g1.sum() > 5000 and g2.sum() > 5000
    # from one frame to the next the highlights move, resize and come and go...
    assert (g1 != g2).sum() > 0.3 * min(g1.sum(), g2.sum())
    # ...and ten frames on they are elsewhere
    g11, _ = _lit(glare, 10.0, 11)
    assert (g1 & g11).sum() < 0.3 * min(g1.sum(), g11.sum())
    # at the same level, another frame seed still moves, resizes or hides them (jitter, flicker)
    g1_other, _ = _lit(glare, 20.0, 7)
    assert (g1 != g1_other).sum() > 0.1 * g1.sum()
    dust = replace(harsh, glare_spots=0)
    _, d1 = _lit(dust, 20.0, 1)
    _, d2 = _lit(dust, 10.0, 2)
    assert d1.sum() > 500
    assert (d1 & d2).sum() < 0.2 * d1.sum()  # the specks drifted away


def test_harsh_stage_wobble_and_lamp_flicker_differ_per_frame():
    from appliance.sim.effects import camera_effects, wobbled

    harsh = PRESETS["harsh"]
    pm = pixel_map(RIG, True)
    shifts = []
    for i in range(12):
        w = wobbled(pm, harsh, np.random.default_rng([1, i]))
        shifts.append((float(pm.x0[0, 0] - w.x0[0, 0]), float(pm.y0[0, 0] - w.y0[0, 0])))
    r = np.hypot(*np.array(shifts).T)
    assert r.max() <= 0.05 + 1e-5 and r.max() > 0.02
    assert len({round(s[0], 5) for s in shifts}) == 12
    only_flicker = Effects(flicker=harsh.flicker)
    means = [
        camera_effects(
            np.full((64, 64, 3), 150.0, np.float32), RIG, only_flicker, pm, np.random.default_rng([1, i])
        ).mean()
        for i in range(12)
    ]
    assert max(means) - min(means) > 1.0 and max(means) <= 150 * 1.015 + 1 and min(means) >= 150 * 0.985 - 1
