"""Surface room: a frame that showed nothing bounds the round summit beneath it (summit.py)."""

import numpy as np

from appliance.sim.ideal import meniscus_waterlines
from appliance.sim.surfaces import Surface, Tier, disc_sdf
from appliance.surface.meniscus import MeniscusModel
from appliance.surface.reconstruct import GridSpec, ReconstructOptions, reconstruct
from appliance.surface.slices import check_waterlines
from appliance.surface.summit import summit_ceiling
from appliance.vision.types import Waterline


def _circle(r, n=64):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.c_[50 + r * np.cos(t), 50 + r * np.sin(t)]


def _slices(first_loops):
    """Frames at 40 (empty), 39 (`first_loops`) and 38 (a disc of radius 20)."""
    slices, _ = check_waterlines(
        [Waterline(40.0, []), Waterline(39.0, first_loops), Waterline(38.0, [_circle(20.0)])]
    )
    return slices


def test_the_empty_frame_above_a_round_summit_is_its_ceiling():
    wets = MeniscusModel(2.5, 0.0)  # on a level face the ink wetting the part rises 0 mm
    assert summit_ceiling(_slices([_circle(5.0)]), wets) == 40.0
    assert summit_ceiling(_slices([_circle(5.0)])) == 40.0


def test_a_knife_edge_rim_is_not_bounded_by_the_empty_frame():
    """A rim with sides steeper than 2 shows first as a band under half a step wide a side:
    the ink climbing its sides keeps it under frames below its top (sample 4's rim)."""
    band = [_circle(5.2), _circle(4.8)[::-1]]  # a ring 0.4 mm wide: 0.2 mm a side
    assert summit_ceiling(_slices(band), MeniscusModel(2.5, 0.0)) == np.inf


def test_a_scan_that_starts_on_the_part_has_no_ceiling():
    slices, _ = check_waterlines([Waterline(39.0, [_circle(5.0)]), Waterline(38.0, [_circle(20.0)])])
    assert summit_ceiling(slices, MeniscusModel(2.5, 0.0)) == np.inf


def _mesa(x, y):
    s = np.clip((np.hypot(x - 50, y - 50) - 10) / 10, 0, 1)
    return 25 - 12 * (3 * s**2 - 2 * s**3)


def test_a_mesa_under_a_meniscus_stands_no_higher_than_the_frame_that_showed_nothing():
    """A flat top at 25 mm (radius 10) on a smooth shoulder, scanned from an empty frame at
    25.4 mm under a wetting ink (l_c 2.5 mm). The rise the shoulder needs (up to 2 mm) was
    carried onto the flat top: measured 27.13 mm at its highest, 0.61 mm off on average over
    the part; with the ceiling held during the top's solve 25.40 and 0.25."""
    part = Surface("mesa", "a mesa", (16.0, 84.0, 16.0, 84.0), (Tier(disc_sdf(50, 50, 30), _mesa),))
    lines = meniscus_waterlines(part, np.arange(25.4, 14.5, -1.0), 2.5, 0.0, resolution_mm=0.3)
    grid = GridSpec(part.bounds, n=(41, 41))
    X, Y = np.meshgrid(*grid.axes())
    z = reconstruct(lines, grid, ReconstructOptions(meniscus=MeniscusModel(2.5, 0.0))).heightmap.z
    on = np.hypot(X - 50, Y - 50) < 28
    assert np.nanmax(z) <= 25.4 + 1e-9
    assert np.nanmean(np.abs(z - part.height(X, Y))[on]) < 0.35
