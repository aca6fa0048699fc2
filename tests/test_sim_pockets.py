"""The virtual bench's held ink: a pocket in the part's top stays full to its spill height
once the free surface drops below its rim, and hides its floor from then on; a hole through
the part drains, and a part with no pocket renders as it did."""

from dataclasses import replace

import numpy as np

from appliance.sim import surfaces as S
from appliance.sim.pockets import SPILL_MM, pool_heights, pool_level, spill_heights
from appliance.sim.render import PRESETS, render_frame

HELD = replace(PRESETS["clean"], trapped_ink=True)


def test_a_pocket_fills_to_the_lowest_point_of_its_rim():
    top = np.full((9, 9), 2.0)  # a floor at 2 ...
    top[1, 1:8] = top[7, 1:8] = top[1:8, 1] = top[1:8, 7] = 10.0  # ... walled in at 10 ...
    top[4, 7] = 7.0  # ... with a notch at 7
    drains = np.zeros(top.shape, bool)
    drains[0, :] = drains[-1, :] = drains[:, 0] = drains[:, -1] = True
    fill = spill_heights(top, drains)
    assert np.all(fill[2:7, 2:7] == 7.0)  # the pool: up to the notch
    assert fill[1, 3] == 10.0 and fill[4, 7] == 7.0  # the rim holds nothing: its own height
    assert np.all(np.isneginf(fill[drains]))


def test_the_craters_bowl_holds_ink_to_its_crest_and_a_hole_through_the_ring_drains():
    (held,) = pool_heights(S.get("crater"))
    assert abs(held - (22.0 - SPILL_MM)) < 0.05  # its crest at 22 mm, level all round
    inside = pool_level(S.get("crater"), np.array([50.0, 62.0]), np.array([50.0, 50.0]))
    outside = pool_level(S.get("crater"), np.array([75.0]), np.array([50.0]))
    assert np.all(inside == np.float32(held)) and np.isnan(outside[0])
    assert pool_heights(S.get("ring")) == ()  # the base lets the ink out under the part
    assert pool_heights(S.get("sample1")) == ()


def _bright(img):
    return img.mean(axis=2) > 90


def test_a_held_pool_hides_the_bowl_below_its_rim():
    # at 8 mm the crater's inner flank stands out of the tank's ink from r 8.2 mm to the
    # crest at r 20; held ink covers it up to 21.9 mm (r 19.3). Seen from 300 mm above the
    # ink, a flank 4-20 mm above it looks 3-14 % larger
    open_, held = (render_frame("crater", 8.0, effects=e) for e in (PRESETS["clean"], HELD))
    lost = _bright(open_) & ~_bright(held)
    assert not (_bright(held) & ~_bright(open_)).any()  # the pool only hides
    px_mm2 = 0.079**2
    flank = np.pi * (19.3**2 - 8.2**2) / px_mm2
    assert 0.95 * flank < lost.sum() < 1.2 * flank


def test_parts_without_a_held_pool_render_as_before():
    for name, level in (("sample1", 20.0), ("ring", 10.0), ("crater", 23.0)):  # 23: over the rim
        a = render_frame(name, level, effects=PRESETS["clean"])
        b = render_frame(name, level, effects=HELD)
        assert np.array_equal(a, b), name
