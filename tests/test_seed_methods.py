"""The dissertation's surface methods (surface/seed.py) on cases with exact answers."""

import numpy as np
import pytest

from appliance.surface import seed


def scattered(f, n=600, seed_=1):
    rng = np.random.default_rng(seed_)
    xy = rng.uniform(0, 100, size=(n, 2))
    return np.column_stack([xy, f(xy[:, 0], xy[:, 1])])


def test_grid_spans_the_points_with_50_cells():
    pts = scattered(lambda x, y: x * 0)
    x, y = seed.seed_grid(pts[:, :2])
    assert len(x) == len(y) == 50
    assert x[0] == pts[:, 0].min() and x[-1] == pts[:, 0].max()


@pytest.mark.parametrize(
    "degree, f",
    [
        (1, lambda x, y: 3 + 0.2 * x - 0.1 * y),
        (2, lambda x, y: 1 + 0.01 * x * x - 0.02 * x * y + 0.005 * y * y + 0.3 * y),
        (3, lambda x, y: 2 + 1e-4 * x**3 - 2e-4 * x * x * y + 3e-4 * x * y * y - 1e-4 * y**3 + 0.1 * x),
    ],
)
def test_least_squares_recovers_its_own_polynomial(degree, f):
    pts = scattered(f)
    x = y = np.linspace(0, 100, 50)
    hm = seed.least_squares(x, y, pts, degree)
    X, Y = np.meshgrid(x, y)
    assert np.max(np.abs(hm.z - f(X, Y))) < 1e-8


def test_lower_degree_cannot_follow_a_cubic():
    f = lambda x, y: 1e-4 * x**3
    pts = scattered(f)
    x = y = np.linspace(0, 100, 50)
    X, Y = np.meshgrid(x, y)
    assert np.max(np.abs(seed.least_squares(x, y, pts, 1).z - f(X, Y))) > 1.0


def test_spline_reproduces_a_plane_inside_the_hull():
    f = lambda x, y: 5 + 0.3 * x + 0.2 * y
    pts = scattered(f, n=2000)
    x = y = np.linspace(10, 90, 20)
    hm = seed.spline(x, y, pts)
    X, Y = np.meshgrid(x, y)
    assert np.max(np.abs(hm.z - f(X, Y))) < 1e-6


def test_nearest_takes_the_closest_point_value():
    pts = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 2.0], [0.0, 10.0, 3.0], [10.0, 10.0, 4.0]])
    hm = seed.nearest(np.array([1.0, 9.0]), np.array([1.0, 9.0]), pts)
    assert hm.z.tolist() == [[1.0, 2.0], [3.0, 4.0]]


def test_as_captured_is_the_highest_level_where_a_cell_was_exposed():
    x = y = np.arange(3.0)
    levels = [30.0, 20.0, 10.0]
    exposed = np.zeros((3, 3, 3), bool)
    exposed[0, 1, 1] = True  # the top cell shows at level 30
    exposed[1, 1, :] = True  # the middle row at 20
    exposed[2] = True  # everything at 10
    exposed[2, 0, 0] = False
    hm = seed.as_captured(x, y, levels, exposed)
    assert hm.z[1, 1] == 30 and hm.z[1, 0] == 20 and hm.z[2, 2] == 10
    assert np.isnan(hm.z[0, 0])  # never exposed: not on the part


def test_unknown_method_is_refused():
    with pytest.raises(ValueError):
        seed.run_method("kriging", np.arange(3.0), np.arange(3.0), np.zeros((3, 3)))
