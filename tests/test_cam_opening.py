"""The planner's screened opening: the full opening where the cutter cannot reach, the design elsewhere."""

import numpy as np
from cam_helpers import grid_map

from appliance.cam import opening as op_mod
from appliance.cam.cutters import parse_cutter
from appliance.cam.opening import Opening
from appliance.cam.sampling import Sampler

BALL = parse_cutter("ball6")
D = 0.1


def _dome_with_groove(X, Y):
    # a gentle dome with a V-groove 1 mm deep and 2 mm wide at y = 20: far tighter than the ball
    dome = 6.0 - 0.004 * ((X - 20) ** 2 + (Y - 20) ** 2)
    groove = np.clip(1.0 - np.abs(Y - 20) / 1.0, 0.0, None)
    return dome - groove


def _both(hm, cutter):
    sm = Sampler(hm, edge_step=D / 2)
    pad = cutter.radius - D / 10
    full = Opening.over(sm, cutter, D, pad=pad)
    screened = Opening.over(sm, cutter, D, pad=pad, screen=True)
    ny, nx = full.z.shape
    X, Y = np.meshgrid(full.x0 + D * np.arange(nx), full.y0 + D * np.arange(ny))
    return sm, full, screened, sm.z(X, Y), sm.on_part(X, Y)


def test_screened_opening_reads_as_the_full_one_for_the_planner():
    hm = grid_map(_dome_with_groove, 0, 40, 0, 40, 0.5)
    sm, full, screened, Z, on = _both(hm, BALL)
    f_above, f_reach = full.above_at(np.full(Z.shape, 10.0), Z, full.z)
    s_above, s_reach = screened.above_at(np.full(Z.shape, 10.0), Z, screened.z)
    # where the cutter cannot reach (the groove), the opening is the full one (to the
    # erosion's single precision)
    out_of_reach = on & (full.z - Z > 0.01)
    assert out_of_reach.sum() > 500
    assert np.allclose(screened.z[out_of_reach], full.z[out_of_reach], rtol=0, atol=1e-5)
    assert np.array_equal(s_reach[on], f_reach[on])
    # elsewhere the design: the stock it measures is never less than the full opening's
    assert np.all(s_above[on] >= f_above[on] - 1e-9)
    assert np.max(s_above[on] - f_above[on]) < 0.002
    # and most of the lattice was never opened in full
    need = op_mod._need(sm, BALL, full.x0, full.y0, Z.shape[1], Z.shape[0], D)
    assert need[out_of_reach].all()
    assert need.mean() < 0.3


def test_steep_parts_and_flat_ends_are_opened_in_full():
    # a hemisphere: its wall is where the opening leaves the design, and a screen would
    # open most of the lattice in full after a coarse pass over all of it
    hm = grid_map(
        lambda X, Y: np.sqrt(np.clip(144 - (X - 15) ** 2 - (Y - 15) ** 2, 0, None)), 0, 30, 0, 30, 0.5
    )
    sm, full, screened, _, _ = _both(hm, BALL)
    assert op_mod._steep_share(sm) >= op_mod.SCREEN_STEEP_SHARE
    assert np.array_equal(screened.z, full.z)
    flat = parse_cutter("flat6")
    _, full, screened, _, _ = _both(grid_map(_dome_with_groove, 0, 40, 0, 40, 0.5), flat)
    assert np.array_equal(screened.z, full.z)
