"""Drop-cutter on shapes with exact answers: a flat, a step, a sphere, a V-groove, an edge."""

import cv2
import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam.cutters import parse_cutter
from appliance.cam.dropcutter import drop_grid, drop_lines, drop_points
from appliance.cam.sampling import Sampler

BALL, FLAT, BULL = parse_cutter("ball6"), parse_cutter("flat6"), parse_cutter("bull6r1")


@pytest.mark.parametrize("cutter", [BALL, FLAT, BULL], ids=["ball", "flat", "bull"])
def test_flat_surface_tip_is_the_surface(cutter):
    hm = grid_map(lambda X, Y: 7.5, 0, 20, 0, 20, 0.5)
    s = Sampler(hm, edge_step=0.05)
    z = drop_points(s, cutter, [5, 10.03, 14.97], [5, 9.99, 15.2])
    assert np.allclose(z, 7.5, atol=1e-9)


def test_sphere_ball_and_flat():
    # a cap of radius 10 on z0 = 5, sampled every 0.1 mm
    rho, zc = 10.0, 5.0
    hm = grid_map(lambda X, Y: zc + np.sqrt(np.maximum(rho**2 - X**2 - Y**2, 0)), -13, 13, -13, 13, 0.1)
    s = Sampler(hm, edge_step=0.05)
    r = np.array([0.0, 1.0, 2.33, 3.7])
    ball = drop_points(s, BALL, r, 0 * r)
    # ball centre rides on the sphere of radius rho + R
    exact = zc + np.sqrt((rho + 3) ** 2 - r**2) - 3
    assert np.max(np.abs(ball - exact)) < 0.002
    assert np.all(ball <= exact + 1e-9)  # the lattice can only under-reach, never over
    rf = np.array([3.5, 5.0, 6.2])
    flat = drop_points(s, FLAT, rf, 0 * rf)
    exact_f = zc + np.sqrt(rho**2 - (rf - 3) ** 2)  # the rim touches where the sphere is highest
    assert np.max(np.abs(flat - exact_f)) < 0.002


@pytest.mark.parametrize("k", [0.5, 1.0, 2.0])
def test_v_groove(k):
    a, xc = 10.0, 20.0
    hm = grid_map(lambda X, Y: a + k * np.abs(X - xc), 0, 40, 0, 20, 0.1)
    s = Sampler(hm, edge_step=0.05)
    z = drop_points(s, BALL, [xc], [10.0])[0]
    assert z == pytest.approx(a + 3 * (np.sqrt(1 + k * k) - 1), abs=0.002)
    z = drop_points(s, FLAT, [xc], [10.0])[0]
    assert z == pytest.approx(a + 3 * k, abs=1e-9)
    z = drop_points(s, BULL, [xc], [10.0])[0]
    # torus tube (radius 1, centre circle radius 2) touching both walls
    assert z == pytest.approx(a + 2 * k + (np.sqrt(1 + k * k) - 1), abs=0.002)


def test_step_wall_is_a_contact_even_between_lattice_points():
    # 10 mm below x = 50, 20 mm from it: a wall the 0.5 mm map turns into one steep cell side
    hm = grid_map(lambda X, Y: np.where(X >= 50, 20.0, 10.0), 30, 70, 0, 20, 0.5)
    s = Sampler(hm, edge_step=0.05)
    x = 47.35  # its offset lattice (x + 0.1 k) straddles the wall top at x = 50
    z = drop_points(s, BALL, [x], [10.0])[0]
    assert z == pytest.approx(20 - (3 - np.sqrt(9 - (50 - x) ** 2)), abs=1e-6)
    # without the wall segments the lattice misses the top corner by ~0.1 mm
    z_lattice = drop_points(Sampler(hm), BALL, [x], [10.0])[0]
    assert z - z_lattice > 0.05
    assert drop_points(s, FLAT, [x], [10.0])[0] == pytest.approx(20.0)
    # the map's wall is a ramp from x = 49.5 to 50: 3.1 mm away it is out of reach
    assert drop_points(s, BALL, [46.4], [10.0])[0] == pytest.approx(10.0)


def test_part_edge_is_a_contact():
    # a plane rising to the part's edge at x = 20; the cutter hanging over the edge
    # touches the edge itself, which no lattice point needs to hit
    hm = grid_map(lambda X, Y: 10 + 0.5 * X, 0, 20, 0, 20, 1.0)
    s = Sampler(hm, edge_step=0.05)
    x = 19.55
    z = drop_points(s, BALL, [x], [10.0])[0]
    assert z == pytest.approx(20 - (3 - np.sqrt(9 - (20 - x) ** 2)), abs=1e-6)
    # further in, the plane itself: centre R / cos(alpha) above it
    z = drop_points(s, BALL, [15.0], [10.0])[0]
    assert z == pytest.approx(10 + 0.5 * 15 + 3 * (np.sqrt(1.25) - 1), abs=0.002)


def test_flat_cutter_is_a_disc_dilation():
    rng = np.random.default_rng(5)
    hm = grid_map(
        lambda X, Y: 5 + np.sin(X / 3) * np.cos(Y / 4) + 0.3 * np.sin(X * Y / 50), 0, 30, 0, 30, 0.1
    )
    hm.z += rng.normal(0, 0.01, hm.z.shape)
    s = Sampler(hm)
    got = drop_grid(s, FLAT, 0.0, 0.0, hm.x.size, hm.y.size, 0.1)
    m = 30
    yy, xx = np.mgrid[-m : m + 1, -m : m + 1]
    disc = ((xx**2 + yy**2) <= (3 / 0.1) ** 2 + 1e-9).astype(np.uint8)
    padded = np.pad(hm.z.astype(np.float32), m, constant_values=0.0)
    ref = cv2.dilate(padded, disc)[m:-m, m:-m]
    assert np.max(np.abs(got - ref)) < 1e-5


def test_lines_at_an_angle_agree_with_a_fine_brute_force():
    hm = grid_map(lambda X, Y: 5 + 0.2 * X + 0.1 * np.sin(Y), 0, 30, 0, 30, 1.0)
    s = Sampler(hm, edge_step=0.05)
    th = np.radians(30)
    e = (np.cos(th), np.sin(th))
    lines = drop_lines(s, BALL, [[5, 5], [5, 8]], e, 50, 0.1)
    px = 5 + 0.1 * np.arange(0, 50, 7) * e[0]
    py = 8 + 0.1 * np.arange(0, 50, 7) * e[1]
    u = np.arange(-3, 3.0001, 0.01)
    U, V = np.meshgrid(u, u)
    r = np.hypot(U, V)
    ok = r <= 3
    brute = [np.max(s.z(x + U[ok], y + V[ok]) - BALL.profile(r[ok])) for x, y in zip(px, py)]
    assert np.max(np.abs(lines[1, ::7] - brute)) < 0.002


def test_flat_end_on_a_slope_touches_with_its_rim_exactly():
    # a plane of gradient (0.24, 0.08): a flat end touches at its rim in the uphill
    # direction, tip = Z(p + R g/|g|). The lattice disc's outermost uphill offsets
    # stop short of the rim (0.007 mm low here); the finishing drop-cutter searches
    # the rim itself.
    from appliance.cam.contact import drop_points as finishing_drop

    g = np.array([0.24, 0.08])
    hm = grid_map(lambda X, Y: 10 + g[0] * X + g[1] * Y, 0, 30, 0, 30, 1.0)
    s = Sampler(hm, edge_step=0.05)
    x, y = np.array([12.0, 15.3]), np.array([11.0, 14.7])
    exact = 10 + g @ np.vstack([x, y]) + 3 * np.hypot(*g)
    lattice = drop_points(s, FLAT, x, y)
    assert np.max(exact - lattice) > 0.003  # what the lattice alone misses
    got = finishing_drop(s, FLAT, x, y)
    assert np.max(np.abs(got - exact)) < 2e-4


@pytest.mark.parametrize("step", [0.5, 0.1])
@pytest.mark.parametrize("cutter", [BALL, FLAT, BULL], ids=["ball", "flat", "bull"])
def test_edge_pairs_left_out_could_not_raise_a_tip(cutter, step, monkeypatch):
    # a footprint with a bay, walls inside it and a rough top, sampled coarsely and at
    # 0.1 mm (patches of ten segments): the pairs the bounds leave out change no tip,
    # and they do leave most of them out
    from appliance.cam import dropcutter

    rng = np.random.default_rng(3)
    hm = grid_map(lambda X, Y: 6 + 0.2 * X + np.where(X > 12, 4.0, 0.0), 0, 24, 0, 20, step)
    hm.z += rng.normal(0, 0.05, hm.z.shape)
    hm.z[np.ix_(hm.y >= 7.5, (hm.x >= 9) & (hm.x < 15))] = np.nan
    s = Sampler(hm, edge_step=0.05)
    origins = np.column_stack([np.full(41, -2.0), np.linspace(-2, 22, 41)])
    kept, total = [], []  # pairs per block of positions (dropcutter._EDGE_POINTS)
    pruned = dropcutter._may_raise

    def counting(*a):
        out = pruned(*a)
        kept.append(out[0].size)
        return out

    def every_pair(*a):
        total.append(a[-2].size)
        return a[-2], a[-1]

    monkeypatch.setattr(dropcutter, "_may_raise", counting)
    got = drop_lines(s, cutter, origins, (1.0, 0.0), 281, 0.1)
    monkeypatch.setattr(dropcutter, "_may_raise", every_pair)
    monkeypatch.setattr(dropcutter, "_patch_may_raise", lambda *a: (a[-2], a[-1]))
    every = drop_lines(s, cutter, origins, (1.0, 0.0), 281, 0.1)
    assert np.array_equal(got, every)
    assert len(kept) == len(total) and sum(kept) < 0.5 * sum(total)


@pytest.mark.parametrize("angle, stride", [(0, 1), (90, 2), (30, 3), (180, 1)])
def test_lines_meet_the_edges_as_the_same_points_one_by_one(angle, stride):
    # the points of lines find their edge segments by arithmetic, scattered points
    # through a k-d tree: both must see the same contacts (a step wall and a bay)
    hm = grid_map(lambda X, Y: 6 + 0.2 * X + np.where(X > 12, 4.0, 0.0), 0, 24, 0, 20, 0.5)
    hm.z[15:, 18:30] = np.nan
    s = Sampler(hm, edge_step=0.05)
    th = np.radians(angle)
    e1 = np.array([np.cos(th), np.sin(th)])
    origins = np.array([[12, 10], [11.05, 14.3], [8, 7.9]]) - 14 * e1
    n = 281
    lines = drop_lines(s, BALL, origins, e1, n, 0.1, stride=stride)
    t = 0.1 * np.arange(0, n, stride)
    px = origins[:, :1] + t[None, :] * e1[0]
    py = origins[:, 1:] + t[None, :] * e1[1]
    points = drop_points(s, BALL, px.ravel(), py.ravel()).reshape(px.shape)
    # (single-precision dilation relative to each slab's top: a few 1e-6 mm apart)
    assert np.max(np.abs(lines - points)) < 2e-5
    bare = drop_lines(Sampler(hm), BALL, origins, e1, n, 0.1, stride=stride)
    assert np.max(lines - bare) > 1.0  # the edges raised some tips


@pytest.mark.parametrize("cutter", [BALL, BULL], ids=["ball", "bull"])
@pytest.mark.parametrize("direction", [(1.0, 0.0), (0.6, 0.8)], ids=["along x", "oblique"])
def test_points_a_sub_step_apart_read_on_one_lattice_are_where_they_are_said_to_be(cutter, direction):
    # drop_fine_lines reads every sub-position on the line's own lattice (offsets a - j / sub
    # steps along it) where the pass ends' fine lines read a lattice centred on each. On a
    # tilted plane the tip is the plane at the axis plus R (sqrt(1 + g^2) - 1) for a ball:
    # a point read a fraction of a step off its place is wrong by the slope times that
    # (0.04 mm), the lattice's own shortfall is h'' d^2 / 8
    from appliance.cam.fineline import fine_lattice_lines as drop_fine_lines

    gx, gy = 0.5, 0.2
    hm = grid_map(lambda X, Y: 20 + gx * X + gy * Y, -20, 20, -20, 20, 0.5)
    s = Sampler(hm, edge_step=0.05)
    e1 = np.array(direction)
    origins = np.array([[-6.0, -2.0], [-6.0, 0.33], [-6.0, 4.1]])
    sub, n = 8, 8 * 60
    fine = drop_fine_lines(s, cutter, origins, e1, n, 0.1, sub, np.ones((len(origins), n), bool))
    centred = np.stack(
        [drop_lines(s, cutter, origins + (j / sub) * 0.1 * e1, e1, n // sub, 0.1) for j in range(sub)], axis=2
    ).reshape(fine.shape)
    # the whole steps are the same (to single precision: each slab is relative to its top)
    assert np.allclose(fine[:, ::sub], centred[:, ::sub], rtol=0, atol=1e-5)
    assert np.max(np.abs(fine - centred)) < 0.002
    if cutter is BALL:
        t = 0.1 / sub * np.arange(n)
        x, y = origins[:, :1] + t * e1[0], origins[:, 1:] + t * e1[1]
        exact = 20 + gx * x + gy * y + 3 * (np.sqrt(1 + gx * gx + gy * gy) - 1)
        assert np.all(fine <= exact + 1e-6) and np.max(exact - fine) < 0.001
