"""Displacement and meniscus: the shared definitions, and the renderer obeying them."""

import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from appliance.sim import physics
from appliance.sim import surfaces as S
from appliance.sim.render import Effects, render_frame
from appliance.sim.rig import Rig

sys.path.insert(0, str(Path(__file__).parent))
from test_sim_render import _crossings, _gray, _to_plane


def _cone_volume_above(L):
    """Exact: the cone's tip above level L (height 3 + tan30 (35 - r))."""
    t = math.tan(math.radians(30))
    top = 3 + t * 35
    if L >= top:
        return 0.0
    if L <= 3:
        return math.pi * 35**2 * (top - 3) / 3 + math.pi * 35**2 * (3 - L)
    h = top - L
    r = h / t
    return math.pi * r * r * h / 3


def test_meniscus_rise_matches_the_figures_in_the_method_doc():
    h = physics.meniscus_rise(np.radians([5, 15, 30, 90]))
    assert np.allclose(h[:3], [0.24, 0.71, 1.40], atol=0.006)
    assert math.isclose(h[3], 2 * 2.7 * math.sin(math.pi / 4))
    assert physics.meniscus_rise(np.radians(20), theta=np.radians(20)) == 0.0


def test_emerged_volume_and_true_level_on_the_cone():
    cone = S.get("cone")
    for L in (5.0, 12.0, 20.0):
        assert abs(physics.emerged_volume(cone, L) - _cone_volume_above(L)) < 2e-3 * _cone_volume_above(L) + 1
    A = 22500.0
    for nominal in (6.0, 15.0, 22.0):
        want = brentq(lambda L: L - nominal + _cone_volume_above(L) / A, nominal - 10, nominal)
        got = physics.true_level(cone, nominal, A)
        assert abs(got - want) < 0.002, (nominal, got, want)
        assert got < nominal
    # ~30 % of a step on a 50 cm^2 waterline in a 225 cm^2 tank (docs/method.md)
    assert abs(physics.emerged_area(S.get("sample1"), 2.0) / A - 0.44) < 0.01


def test_ripple_decays():
    a0 = physics.ripple_amplitude(0.2, 0.0, 0.5)
    a1 = physics.ripple_amplitude(0.2, 1.0, 0.5)
    assert a0 == 0.2 and math.isclose(a1, 0.2 * math.exp(-2))
    off = physics.ripple_offset(np.array([10.0, 60.0]), np.array([20.0, 80.0]), 0.2, 3.0)
    assert np.abs(off).max() <= 0.2 * math.exp(-3 / 0.6) + 1e-9


def test_rendered_meniscus_is_the_contact_line_in_perspective():
    """Cone (30 degrees everywhere): the ink climbs h = 2 l_c sin(15 deg) = 1.398 mm.
    The edge seen is the contact line at L + h, projected from that height."""
    cone, L, rig = S.get("cone"), 8.0, Rig()
    img = render_frame(cone, L, rig, Effects(meniscus=True))
    uv = np.vstack([_crossings(_gray(img), 1), _crossings(_gray(img), 0)])
    P0 = _to_plane(rig, uv)
    assert uv.shape[0] > 500
    h = float(physics.meniscus_rise(math.radians(30)))
    C = rig.centre
    Pc = P0 + (C[:2] - P0) * h / C[2]
    err = np.abs(cone.level_sdf(Pc[:, 0], Pc[:, 1], L + h))
    print(
        f"meniscus contact line: max {err.max():.5f} mm; boundary moved "
        f"{np.median(np.abs(cone.level_sdf(P0[:, 0], P0[:, 1], L))):.3f} mm inwards"
    )
    assert err.max() < 0.01
    # and it really moved: the free-surface waterline is h / tan(30) = 2.4 mm further out
    assert np.median(cone.level_sdf(P0[:, 0], P0[:, 1], L)) > 2.0


def test_rendered_displacement_lowers_the_waterline():
    cone, rig = S.get("cone"), Rig()
    nominal = 10.0
    true = physics.true_level(cone, nominal, rig.tank_area_mm2)
    img = render_frame(cone, nominal, rig, Effects(displacement=True))
    uv = _crossings(_gray(img), 1)
    P0 = _to_plane(rig, uv)  # on the ink at rest, where the camera was calibrated
    # the camera is fixed to the tank: the fallen ink is d further away, and its waterline
    # is (H + d) / H as far from the camera's foot as the calibrated plane puts it
    C, d = rig.centre, nominal - true
    P = C[:2] + (P0 - C[:2]) * (C[2] + d) / C[2]
    assert np.abs(cone.level_sdf(P[:, 0], P[:, 1], true)).max() < 0.002
    # read on the plane at rest it is off by r d / H (23 mm x 0.35 mm / 300 mm = 0.027 mm)
    assert np.median(np.abs(cone.level_sdf(P0[:, 0], P0[:, 1], true))) > 0.02
    assert np.median(np.abs(cone.level_sdf(P[:, 0], P[:, 1], nominal))) > 0.1


def test_rendered_contact_line_obeys_the_model_right_up_to_the_walls():
    """Sample 1 (a block: a sculptured top with walls all round) at 9 mm: every edge
    point off the walls is the contact line at L + h(beta), beta the top's slope where
    the contact line is, seen from that height - also within a few mm of a wall, where
    the ink pins at the edge instead of climbing the top with the wall's 3.8 mm."""
    part, L, rig = S.get("sample1"), 9.0, Rig()
    img = render_frame(part, L, rig, Effects(meniscus=True))
    uv = np.vstack([_crossings(_gray(img), 1), _crossings(_gray(img), 0)])
    P = _to_plane(rig, uv)
    edge = np.minimum.reduce([P[:, 0], 100 - P[:, 0], P[:, 1], 100 - P[:, 1]])
    P = P[edge > 0.5]  # the walls themselves are no contact line
    C = rig.centre
    Q = P.copy()
    for _ in range(4):  # contact point, its slope, its rise
        e = 1e-3
        gx = (part.height(Q[:, 0] + e, Q[:, 1]) - part.height(Q[:, 0] - e, Q[:, 1])) / (2 * e)
        gy = (part.height(Q[:, 0], Q[:, 1] + e) - part.height(Q[:, 0], Q[:, 1] - e)) / (2 * e)
        h = physics.meniscus_rise(np.arctan(np.hypot(gx, gy)))
        Q = P + (C[:2] - P) * (h / C[2])[:, None]
    resid = part.height(Q[:, 0], Q[:, 1]) - (L + h)
    near = np.minimum.reduce([Q[:, 0], 100 - Q[:, 0], Q[:, 1], 100 - Q[:, 1]]) < 5
    assert near.sum() > 50
    print(
        f"contact line vs model: {P.shape[0]} points, max |resid| {np.abs(resid).max():.4f} mm, "
        f"within 5 mm of a wall {np.abs(resid[near]).max():.4f} mm ({near.sum()} points)"
    )
    assert np.abs(resid).max() < 0.01  # was 0.15-2.6 mm before the renderer's fixes


SECOND_INK = Effects(
    meniscus=True, capillary_length_mm=2.3, contact_angle_deg=35.0, contact_line_curvature=True
)


def test_second_model_rise_is_a_depression_on_flat_faces_and_follows_the_lines_bend():
    theta = math.radians(35)
    flat, steep = physics.meniscus_rise_curved(np.radians([0.0, 60.0]), 0.0, 2.3, theta)
    assert (
        math.isclose(flat, -2 * 2.3 * math.sin(theta / 2)) and flat < -1.3
    )  # flatter than 35 deg: below the ink
    assert steep > 0
    # a line bending round the part (a peak, kappa > 0) lowers the meniscus, round the ink raises it
    beta = np.radians(50.0)
    straight = physics.meniscus_rise(beta, 2.3, theta)
    peak, pit = physics.meniscus_rise_curved(beta, np.array([0.1, -0.1]), 2.3, theta)
    assert 0.85 * straight < peak < 0.9 * straight and 1.08 * straight < pit < 1.12 * straight
    # a depression shrinks and grows the same way
    assert abs(physics.meniscus_rise_curved(0.0, 0.1, 2.3, theta)) < abs(flat)


def test_second_model_keeps_a_flat_top_dry_under_the_ink():
    """The mesa's flat top is 25 mm up; with the ink 0.8 mm above it the first ink covers
    it, the second (35 deg, depressed 1.38 mm on a flat) leaves it out."""
    part, rig = S.get("plateau"), Rig()
    first = _gray(render_frame(part, 25.8, rig, Effects(meniscus=True)))
    second = _gray(render_frame(part, 25.8, rig, SECOND_INK))
    ink = float(np.median(first))
    assert (first > ink + 40).sum() == 0
    # a disc of radius ~22 mm: ~240 000 pixels of 0.079 mm
    assert (second > ink + 40).sum() > 150_000


def test_second_model_sheds_a_lower_tiers_face_whatever_the_wall_beside_it():
    """The stepped block's 12 mm tier (a face tilted 0.6 deg) with the ink at 12.9 mm: the
    face is dry wherever it stands less than the depression (1.36 mm) under the ink, as a
    single-tier top would be. The upper tier's wall, 0-35 mm away, lifts the ink on
    itself only: the face used to come out only where the ink was 0.2 mm deep."""
    part, rig, L = S.get("stepped-block"), Rig(), 12.9
    img = _gray(render_frame(part, L, rig, SECOND_INK))
    seen_mm2 = (img > float(np.median(img)) + 40).sum() * 0.079**2
    x, y = np.meshgrid(np.arange(8, 92, 0.1), np.arange(10, 86, 0.1))
    upper = (x > 44) & (x < 87) & (y > 20) & (y < 64)  # 30 mm up: always out
    depression = physics.meniscus_rise(np.radians(0.6), 2.3, np.radians(35))
    face_out = ~upper & (part.height(x, y) > L + depression)
    want_mm2 = (upper.sum() + face_out.sum()) * 0.01
    print(f"seen {seen_mm2:.0f} mm^2, upper tier and dry face {want_mm2:.0f} mm^2")
    assert face_out.sum() * 0.01 > 4000  # most of the 4 500 mm^2 face is dry
    assert abs(seen_mm2 - want_mm2) < 0.05 * want_mm2  # was 1 730 mm^2 against 5 980


def test_rendered_second_model_is_the_contact_line_with_its_own_curvature():
    """The crater at 15 mm: contact lines on the ridge's outer flank (bending round the
    part) and in the crater (bending round the ink). Every edge point is the contact line
    at L + h(beta, kappa) seen from that height; the straight-line rise misses both
    flanks, in opposite directions."""
    from scipy import ndimage

    from appliance.sim.render import curvature_grid, surface_grid

    part, L, rig = S.get("crater"), 15.0, Rig()
    img = render_frame(part, L, rig, SECOND_INK)
    uv = np.vstack([_crossings(_gray(img), 1), _crossings(_gray(img), 0)])
    P = _to_plane(rig, uv)
    P = P[np.hypot(P[:, 0] - 50, P[:, 1] - 50) < 40]  # off the disc's wall
    grid = surface_grid(part)
    kgrid = np.asarray(curvature_grid(part)[0][..., 0], float)
    C, theta = rig.centre, math.radians(35)

    def residual(curved):
        Q = P.copy()
        for _ in range(4):  # contact point, its slope and bend, its rise
            e = 1e-3
            gx = (part.height(Q[:, 0] + e, Q[:, 1]) - part.height(Q[:, 0] - e, Q[:, 1])) / (2 * e)
            gy = (part.height(Q[:, 0], Q[:, 1] + e) - part.height(Q[:, 0], Q[:, 1] - e)) / (2 * e)
            beta = np.arctan(np.hypot(gx, gy))
            ix, iy = grid.coords(Q[:, 0], Q[:, 1])
            kappa = ndimage.map_coordinates(kgrid, [iy, ix], order=1) if curved else 0.0
            h = physics.meniscus_rise_curved(beta, kappa, 2.3, theta)
            Q = P + (C[:2] - P) * (h / C[2])[:, None]
        return part.height(Q[:, 0], Q[:, 1]) - (L + h), np.hypot(Q[:, 0] - 50, Q[:, 1] - 50)

    resid, r = residual(True)
    inner, outer = r < 20, r > 20
    assert inner.sum() > 200 and outer.sum() > 200
    print(f"crater contact line vs the second model: max |resid| {np.abs(resid).max():.4f} mm")
    assert np.abs(resid).max() < 0.01
    straight, _ = residual(False)
    # in the crater the line stands higher than a straight one would, outside lower
    assert np.median(straight[inner]) > 0.05 and np.median(straight[outer]) < -0.03
