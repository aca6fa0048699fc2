"""Work done in pieces gives what the whole would: the polyline thinned between kept points,
and the exact wall contacts told the tip already known."""

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam import polyline
from appliance.cam.contact import facet_contacts
from appliance.cam.cutters import parse_cutter
from appliance.cam.polyline import reduce_polyline
from appliance.cam.sampling import Sampler


def test_a_long_run_thinned_piece_by_piece_keeps_the_same_points(monkeypatch):
    t = np.linspace(0, 40, 4001)
    run = np.column_stack([t, 5 * np.sin(t), 0.3 * np.cos(3 * t)])
    keep = np.zeros(len(t), bool)
    keep[::500] = True
    whole = reduce_polyline(run, 0.01, keep)
    monkeypatch.setattr(polyline, "_PIECE", 600)
    pieced = reduce_polyline(run, 0.01, keep)
    assert len(whole) > 100
    np.testing.assert_array_equal(pieced, whole)


def test_wall_contacts_told_the_known_tip_skip_only_cells_that_could_not_raise_it():
    hm = grid_map(lambda X, Y: np.where(X >= 50, 20.0 + 0.2 * Y, 10.0), 30, 70, 0, 20, 0.5)
    s, ball = Sampler(hm), parse_cutter("ball6")
    px = np.linspace(46.0, 49.9, 40)
    py = np.full_like(px, 10.0)
    free = facet_contacts(s, ball, px, py, px, py, cells=6)
    low = np.arange(px.size) % 2 == 1
    known = free + np.where(low, -0.5, 0.5)  # below the exact tip at odd points, above at even
    told = facet_contacts(s, ball, px, py, px, py, cells=6, floor=known)
    np.testing.assert_allclose(np.maximum(told, known), np.maximum(free, known))
    met = low & np.isfinite(free)
    assert met.sum() > 5
    np.testing.assert_allclose(told[met], free[met])  # where the known tip was low, the wall still met


@pytest.mark.parametrize("cutter", ["ball6", "flat6", "ball1"])
def test_a_move_direction_shared_by_every_element_gives_the_same_bits(cutter):
    # min_over_segment with the move given once (a scalar direction: the planner's moves
    # between positions, a cell's sides) takes a shorter path; it must be the same numbers
    from appliance.cam.segments import min_over_segment

    rng = np.random.default_rng(1)
    c = parse_cutter(cutter)
    n = 20_000
    dx, dy = (rng.uniform(-1.3, 1.3, n) * c.diameter for _ in range(2))
    wz, az = rng.uniform(-3, 3, n), rng.uniform(-5, 5, n)
    for wx, wy in [(0.1, 0.0), (1.28, 1.28), (0.0, 1.28), (-0.3, 0.7)]:
        shared = min_over_segment(c, dx, dy, wx, wy, wz, az)
        each = min_over_segment(c, dx, dy, np.full(n, wx), np.full(n, wy), wz, az)
        assert np.isfinite(shared).sum() > n // 10
        assert np.array_equal(shared, each)
