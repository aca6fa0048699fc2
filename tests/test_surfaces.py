"""The virtual bench's parts: the dissertation samples against their printed appendices,
and the signed distance to the waterline that the renderer and the accuracy tests rely on."""

import numpy as np
import pytest

from appliance.sim import surfaces


def diss(name, x, y):
    s = surfaces.get(name)
    return s.to_dissertation(s.height(np.array(x, float), np.array(y, float)))


def test_sample3_reproduces_appendix_d():
    xs = [0, 0.757602, 1.515358, 2.273423, 3.031952]
    assert diss("sample3", xs, [0] * 5) == pytest.approx([45, 44.2925, 43.62403, 42.99385, 42.4012], abs=5e-5)
    assert diss("sample3", [100], [0])[0] == pytest.approx(46, abs=1e-6)
    assert diss("sample3", [0, 0.757602], [0.757602] * 2) == pytest.approx([45.0609, 44.35516], abs=5e-5)


def test_sample2_reproduces_appendix_c():
    xs = [0, 2.040816, 4.081633, 6.122449, 8.163265]
    assert diss("sample2", xs, [4.081633] * 5) == pytest.approx(
        [-17.31, -17.31, -17.31, -17.3102, -17.3107], abs=6e-5
    )


def test_sample1_reproduces_appendix_b_corner():
    assert diss("sample1", [0, 2.040857], [0, 0]) == pytest.approx(
        [-32.4225, -32.2794], abs=5e-3
    )  # a fit, exact to ~3 um (docs/method.md)


@pytest.mark.parametrize("name", list(surfaces.SURFACES))
def test_every_part_stands_on_the_base(name):
    s = surfaces.get(name)
    X, Y = s.sample_grid(120)
    z = s.height(X, Y)
    inside = s.inside(X, Y)
    assert np.all(z[inside] > 0) or name in ("ring", "sphere", "cone")
    assert np.all(z[~inside] == 0)
    assert s.z_max > 5


@pytest.mark.parametrize("name", ["sample1", "sample3", "twin-peaks", "ring", "plateau"])
def test_level_sdf_is_a_distance_near_the_waterline(name):
    """Stepping along the sdf's gradient by d lands on the level curve to < 1 micrometre."""
    s = surfaces.get(name)
    level = 0.5 * (s.z_max + float(np.min(s.height(*s.sample_grid(60))[s.inside(*s.sample_grid(60))])))
    rng = np.random.default_rng(3)
    xmin, xmax, ymin, ymax = s.bounds
    p = np.column_stack([rng.uniform(xmin, xmax, 4000), rng.uniform(ymin, ymax, 4000)])
    d = s.level_sdf(p[:, 0], p[:, 1], level)
    near = np.abs(d) < 0.05
    p, d = p[near], d[near]
    assert len(p) > 10
    eps = 1e-5
    gx = (s.level_sdf(p[:, 0] + eps, p[:, 1], level) - s.level_sdf(p[:, 0] - eps, p[:, 1], level)) / (2 * eps)
    gy = (s.level_sdf(p[:, 0], p[:, 1] + eps, level) - s.level_sdf(p[:, 0], p[:, 1] - eps, level)) / (2 * eps)
    g = np.hypot(gx, gy)[:, None]
    on_curve = p - d[:, None] * np.column_stack([gx, gy]) / g
    residual = s.level_sdf(on_curve[:, 0], on_curve[:, 1], level)
    assert np.max(np.abs(residual)) < 1e-3
    # away from the walls the level curve is where the top's height is the level
    fp = np.max([t.footprint(on_curve[:, 0], on_curve[:, 1]) for t in s.tiers], axis=0)
    off_wall = fp > 0.1
    h = s.height(on_curve[off_wall, 0], on_curve[off_wall, 1])
    assert np.max(np.abs(h - level), initial=0) < 0.005


def test_ring_has_a_hole_down_to_the_base():
    ring = surfaces.get("ring")
    assert ring.height(50, 50) == 0 and not ring.inside(50, 50)
    assert ring.height(50 + 30, 50) == pytest.approx(20)


def test_unknown_surface_names_the_choices():
    with pytest.raises(Exception, match="unknown surface 'teapot'"):
        surfaces.get("teapot")
