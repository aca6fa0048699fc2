"""The rim is finished: a program with margin RIM runs off the part's outline onto the base,
and `verify` measures the whole surface the cutter can reach, its edge included (issue 20)."""

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam.contact import drop_points
from appliance.cam.cutters import parse_cutter
from appliance.cam.gcodeparse import parse_gcode
from appliance.cam.jobs import finishing_gcode, verify_gcode
from appliance.cam.sampling import Sampler
from appliance.cam.zigzag import RIM, FinishSettings, finishing, steep_outline


def _dome(X, Y):
    # a dome falling towards every edge, about 1.4 mm above the base there (less than the radius: the base holds the tip): the strip along the
    # edge can only be reached by a cutter whose axis is outside the outline
    return 1 + 6 * np.exp(-((X - 10) ** 2 + (Y - 8) ** 2) / 60)


@pytest.mark.parametrize("cutter,h", [("ball4", 0.05), ("flat4", 0.05)])
def test_a_rim_program_finishes_the_rim_and_verify_measures_all_of_it(cutter, h):
    hm = grid_map(_dome, 0, 20, 0, 16, 0.5)
    job = finishing_gcode(hm, FinishSettings(parse_cutter(cutter), scallop=h, margin=RIM))
    rep, _ = verify_gcode(job.text, hm)  # no edge band by default
    assert rep.measured_area == pytest.approx(rep.part_area - rep.unreachable_area)
    assert rep.unreachable_area < 0.01 * rep.part_area  # the rim counts as reachable
    assert rep.uncut_reachable <= 0.01
    assert abs(rep.scallop_max - h) <= 0.1 * h, rep.lines()
    assert rep.gouge <= 0.005


def test_the_passes_run_off_the_outline_onto_the_base_and_never_below_it():
    hm = grid_map(_dome, 0, 20, 0, 16, 0.5)
    ball = parse_cutter("ball4")
    p = parse_gcode(finishing_gcode(hm, FinishSettings(ball, scallop=0.05, margin=RIM)).text)
    z0 = -float(p.meta("inkslice z_offset") or 0.0)
    cut = (p.kind == 1) & np.isfinite(p.xyz).all(axis=1)
    x, y, z = p.xyz[cut].T
    outside = (x < 0) | (x > 20) | (y < 0) | (y > 16)
    assert outside.any() and x.min() < -1.5 and y.max() > 17.5  # up to a radius (2 mm) less a step
    assert x.min() >= -2 and x.max() <= 22 and y.min() >= -2 and y.max() <= 18
    assert (z + z0).min() >= -1e-6  # the tip never goes below the base top


def test_the_default_program_finishes_the_rim_and_margin_0_leaves_it_uncut():
    hm = grid_map(_dome, 0, 20, 0, 16, 0.5)
    ball = parse_cutter("ball4")
    default = FinishSettings(ball, scallop=0.05)
    assert default.rim and default.margin == FinishSettings(ball, scallop=0.05, margin=RIM).margin
    rep, _ = verify_gcode(finishing_gcode(hm, default).text, hm, edge_band=0.0)
    assert rep.uncut_reachable <= 0.01 and rep.scallop_max <= 0.055, rep.lines()
    inside, _ = verify_gcode(finishing_gcode(hm, FinishSettings(ball, scallop=0.05, margin=0.0)).text, hm)
    assert inside.uncut_reachable > 0.02 or inside.scallop_max > 0.2, inside.lines()


def test_where_a_pass_rolls_over_the_outline_no_move_runs_below_the_cutters_tip():
    # off the part the tip follows the cutter rolling about the edge, sharply concave: the
    # moves there are refined where they would cut in, then thinned
    hm = grid_map(_dome, 0, 20, 0, 16, 0.5)
    st = FinishSettings(parse_cutter("ball4"), scallop=0.05, margin=RIM)
    sampler = Sampler(hm, edge_step=st.resolution / 2)
    fin = finishing(sampler, st)
    a = np.vstack([r[:-1] for r in fin.runs])
    b = np.vstack([r[1:] for r in fin.runs])
    off = ~sampler.on_part(a[:, 0], a[:, 1]) | ~sampler.on_part(b[:, 0], b[:, 1])
    a, b = a[off], b[off]
    assert len(a) > 100  # the passes do roll over the outline
    u = np.linspace(0, 1, 9)[1:-1]
    p = (a[:, None, :] + u[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3)
    tip = drop_points(sampler, st.cutter, p[:, 0], p[:, 1], st.resolution)
    # thinning holds the dropped points within the chord tolerance; between them a move may
    # pass a little lower (0.00212 measured)
    assert np.max(tip - p[:, 2]) <= 1.1 * st.chord


def test_a_flat_end_runs_off_the_outline_to_a_tenth_of_a_step_short_of_its_radius_at_both_ends():
    # a flat bottom reaches a cell at the outline only from within R of it, so a position a
    # step short of the radius leaves the slope times the step there (sample 3's corner,
    # benches/cam.py --only rim); on whole steps from the near end the far end stopped up to
    # a step shorter still, so the positions close up to end on the margin at both ends
    hm = grid_map(_dome, 0, 20.03, 0, 16, 0.5 * 20.03 / 20)
    flat = parse_cutter("flat4")
    st = FinishSettings(flat, scallop=0.05, margin=RIM)
    assert st.margin == pytest.approx(2 - st.resolution / 10)
    p = parse_gcode(finishing_gcode(hm, st).text)
    cut = (p.kind == 1) & np.isfinite(p.xyz).all(axis=1)
    x, y = p.xyz[cut, 0], p.xyz[cut, 1]
    x0, x1 = float(hm.x[0]), float(hm.x[-1])
    assert x.min() == pytest.approx(x0 - st.margin, abs=1e-4)
    assert x.max() == pytest.approx(x1 + st.margin, abs=1e-4)
    assert y.min() == pytest.approx(-st.margin, abs=1e-4) and y.max() == pytest.approx(
        16 + st.margin, abs=1e-4
    )
    # a ball and a bull nose too: a whole step short, a 1 mm ball's side at the outline was
    # 74 degrees (asin 0.48 / 0.5), short of sample 4's 80-degree faces beside it, and the
    # strip the verification reaches from further out was left at 0.0371 for 0.01 asked
    ball = FinishSettings(parse_cutter("ball1"), scallop=0.01, resolution=0.02, margin=RIM)
    assert np.degrees(np.arcsin(ball.margin / 0.5)) > 82
    assert FinishSettings(parse_cutter("ball4"), margin=RIM).margin == pytest.approx(2 - 0.01)
    assert FinishSettings(parse_cutter("bull4r1"), margin=RIM).margin == pytest.approx(2 - 0.01)


def test_a_ball_runs_a_tenth_short_only_where_a_face_at_the_outline_is_steeper_than_its_side():
    # a step short, a 2 mm ball's side at the outline is asin(1.9 / 2) = 72 degrees: enough for
    # the dome, whose faces there are gentle, and its positions stay on the lattice's phase
    gentle = grid_map(_dome, 0, 20, 0, 16, 0.5)
    assert not steep_outline(Sampler(gentle), 2.0, 1.9)
    fin = finishing(
        Sampler(gentle, edge_step=0.05), FinishSettings(parse_cutter("ball4"), scallop=0.05, margin=RIM)
    )
    assert fin.margin == pytest.approx(2 - 0.1)
    # a face falling at 80 degrees to the far edge is not reached to its edge from 1.9 mm out
    wall = grid_map(lambda X, Y: 1 + np.minimum(np.tan(np.radians(80)) * (20 - X), 6), 0, 20, 0, 16, 0.5)
    assert steep_outline(Sampler(wall), 2.0, 1.9)
    assert not steep_outline(Sampler(wall), 2.0, 1.99)  # a tenth short: its side is 84 degrees


def test_near_the_machines_travel_the_rim_runs_off_only_as_far_as_it_reaches():
    # the map starts 1 mm inside the default machine's X travel (-10): a radius off the
    # outline would leave it; the program runs 0.99 mm off and says so, rather than none
    hm = grid_map(lambda X, Y: _dome(X + 9, Y), -9, 11, 0, 16, 0.5)
    job = finishing_gcode(hm, FinishSettings(parse_cutter("ball4"), scallop=0.05))
    x = parse_gcode(job.text).xyz[:, 0]
    assert np.nanmin(x) >= -10.0 - 1e-9 and np.nanmin(x) < -9.5, np.nanmin(x)
    assert "the machine's travel ends there" in job.text


def _round_block(X, Y):
    # a dome on a round block, coarse as the daemon's maps: its wall stands 4-5 mm at the outline
    r2 = (X - 12) ** 2 + (Y - 12) ** 2
    return np.where(r2 <= 81, 4 + 3 * np.exp(-r2 / 40), np.nan)


def test_the_distance_to_a_round_outline_is_exact_not_a_cell_off():
    hm = grid_map(_round_block, 0, 24, 0, 24, 1.2)
    sampler = Sampler(hm)
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-4, 28, 4000), rng.uniform(-4, 28, 4000)
    # brute force: the nearest on-part cell, each a rectangle
    j, i = np.nonzero(sampler.cell_on)
    cx, cy = hm.x[i] + 0.6, hm.y[j] + 0.6
    gx = np.maximum(np.abs(x[:, None] - cx[None]) - 0.6, 0)
    gy = np.maximum(np.abs(y[:, None] - cy[None]) - 0.6, 0)
    truth = np.hypot(gx, gy).min(axis=1)
    np.testing.assert_allclose(sampler.part_distance(x, y), truth, atol=1e-9)


def test_off_a_wall_at_a_round_outline_no_pass_runs_past_the_cutters_reach():
    # beyond R from the part a ball's tip falls from the wall's top less R to the base: a
    # position kept there (the margin judged a cell off) made a move that cut into the wall
    hm = grid_map(_round_block, 0, 24, 0, 24, 1.2)
    st = FinishSettings(parse_cutter("ball4"), scallop=0.05, margin=RIM)
    sampler = Sampler(hm, edge_step=st.resolution / 2)
    fin = finishing(sampler, st)
    pts = np.vstack(fin.runs)
    assert sampler.part_distance(pts[:, 0], pts[:, 1]).max() <= st.cutter.radius
    assert pts[:, 2].min() > 1.0  # every position still leans on the wall
    rep, _ = verify_gcode(finishing_gcode(hm, st).text, hm)
    assert rep.gouge <= 0.005, rep.lines()


def _ball_seen_from_above(X, Y):
    # the demo's part, smaller: a ball whose outline the camera saw 0.6 mm inside its equator,
    # so the map ends on a 75-degree face 4 mm above the base, along the passes at its ends
    r2 = (X - 18.4) ** 2 + (Y - 18.4) ** 2
    return np.where(r2 <= 17.4**2, np.sqrt(np.maximum(18.0**2 - r2, 0.0)), np.nan)


def test_a_wall_along_the_passes_at_the_outline_is_finished_to_its_top_edge():
    # the pass run off the outline meets the wall's top edge only at the full radius; the
    # step from it went unmeasured and left a 1.6 mm ridge along the edge (0.45 % uncut)
    hm = grid_map(_ball_seen_from_above, 0, 36.8, 0, 36.8, 1.18)
    job = finishing_gcode(hm, FinishSettings(parse_cutter("ball6"), scallop=0.05))
    rep, _ = verify_gcode(job.text, hm)
    assert rep.uncut_reachable <= 0.001, rep.lines()
    assert rep.scallop_max <= 0.1, rep.lines()  # 0.064 at the outline's diagonal corners
    assert rep.gouge <= 0.005
