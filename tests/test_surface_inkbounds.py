"""The floor and ceiling the frames give each node (surface/inkbounds.py), where they clash."""

import numpy as np

from appliance.surface.inkbounds import NodeBounds, _without_clashes, held, under_flat_ink
from appliance.surface.lattice import Lattice
from appliance.surface.slices import make_slice


def test_a_node_out_of_the_ink_above_where_ink_was_seen_over_it_keeps_neither_bound():
    # node 0: consistent (out at 5, ink at 8); node 1: out at 35 but ink seen at 17.5 (a
    # waterline's noise at a wall's edge: harsh sample 4 stood 21 mm low held to it)
    both = np.array([True, True])
    b = NodeBounds(both, np.array([5.0, 35.0]), np.array([8.0, 17.5]), both)
    out = _without_clashes(b)
    assert out.floor[0] == 5.0 and out.ceiling[0] == 8.0 and out.hidden[0] and out.ray[0]
    assert out.floor[1] == -np.inf and out.ceiling[1] == np.inf and not out.hidden[1]
    assert not out.ray[1]


def test_a_ray_over_a_rim_holds_every_node_a_frames_ink_only_the_hidden():
    # nodes: hidden under a level ceiling; seen, under a ray over a rim; seen, under a
    # level ceiling (a waterline's noise at a wall's edge may have put it there); and a
    # node below its floor
    b = NodeBounds(
        np.array([True, False, False, False]),
        np.array([0.0, 0.0, 0.0, 6.0]),
        np.array([5.0, 5.0, 5.0, np.inf]),
        np.array([False, True, False, False]),
    )
    assert held(np.array([7.0, 7.0, 7.0, 4.0]), b).tolist() == [5.0, 5.0, 7.0, 6.0]


def test_in_polygon_agrees_with_opencvs_point_polygon_test_on_and_off_the_loop():
    # lattice nodes (few rows, many on a vertex or a level edge of a half-mm loop) and loose
    # points: inside exactly where cv2.pointPolygonTest says > 0, a point on the loop out
    import cv2

    from appliance.surface.inkbounds import in_polygon

    rng = np.random.default_rng(5)
    th = np.sort(rng.uniform(0, 2 * np.pi, 80))
    loop = np.round(np.column_stack([9 * np.cos(th), 6 * np.sin(th)]) * 2) / 2
    X, Y = np.meshgrid(np.arange(-10, 10.01, 0.5), np.arange(-7, 7.01, 0.5))
    q = np.vstack([np.column_stack([X.ravel(), Y.ravel()]), loop, rng.uniform(-10, 10, (300, 2))])
    poly = loop.astype(np.float32).reshape(-1, 1, 2)
    want = np.array([cv2.pointPolygonTest(poly, (float(x), float(y)), False) > 0 for x, y in q])
    on_loop = np.array([cv2.pointPolygonTest(poly, (float(x), float(y)), False) == 0 for x, y in q])
    assert on_loop.sum() > 80 and 0 < want.sum() < len(q)  # the edge cases are there
    np.testing.assert_array_equal(in_polygon(loop, q), want)


def test_a_node_far_under_the_ink_is_held_to_the_inks_flat_surface():
    """The ink covering a node one frame up is level a few capillary lengths from where it
    climbs the part: a node 3 l_c out stands at most rise_max e^-3 above that level. Next to
    the waterline (its side there not sure) and at the first frame nothing is said."""
    lat = Lattice(np.linspace(0.0, 40.0, 81), np.linspace(0.0, 40.0, 81))  # 0.5 mm apart
    a = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    ring = lambda r: [np.column_stack([20.0 + r * np.cos(a), 20.0 + r * np.sin(a)])]
    slices = [make_slice(10.0, ring(5.0)), make_slice(9.0, ring(18.0))]
    X, Y = np.meshgrid(lat.x, lat.y)
    r = np.hypot(X - 20.0, Y - 20.0)
    first = np.where(r < 5.0, 0, np.where(r < 18.0, 1, 2))
    rise_max, lc = 3.8, 2.7
    top = under_flat_ink(lat, first, slices, rise_max, lc)
    node = (r >= 5.0 + 3.0 * lc) & (r < 5.5 + 3.0 * lc)
    assert node.any() and np.allclose(top[node], 10.0 + rise_max * np.exp(-(r[node] - 5.0) / lc), atol=0.01)
    assert np.all(top[node] <= 10.0 + 0.05 * rise_max)  # e^-3 = 0.0498
    assert np.all(np.isinf(top[(first == 1) & (r < 5.9)]))  # within two spacings of the waterline
    assert np.all(np.isinf(top[first == 0])) and np.all(np.isinf(top[first == 2]))
    assert np.all(np.isinf(under_flat_ink(lat, first, slices, 0.0, lc)))  # no meniscus: the bracket's
