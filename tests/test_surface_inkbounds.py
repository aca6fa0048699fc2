"""The floor and ceiling the frames give each node (surface/inkbounds.py), where they clash."""

import numpy as np

from appliance.surface.inkbounds import NodeBounds, _without_clashes, held


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
