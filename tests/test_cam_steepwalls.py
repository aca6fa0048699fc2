"""Walls of 84-85 degrees on a 0.2 mm map: the drop-cutter meets them exactly, so neither
finishing nor rest machining cuts into them (issue 20, benches/steep.py).

On a face that steep the cutter touches within a few hundredths of a millimetre of its
rim, where h'' = 1 / (R cos^3) is ~500 /mm for a 6 mm ball: a contact found 0.015 mm
off reads 0.06 mm low, and `verify` measures that as a gouge (vertically, as it
measures everything)."""

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam.contact import drop_points, facet_contacts
from appliance.cam.cutters import parse_cutter
from appliance.cam.jobs import verify_gcode
from appliance.cam.operations import Operation, plan_operations, post_operations
from appliance.cam.sampling import Sampler
from appliance.cam.tools import Tool
from appliance.cam.waterline import FOOT, SteepSettings, regions, tip_field, waterlines

WALL_DEG = 85.0
# verify's gouge tolerance (jobs: --max-gouge's lattice); the acceptance is "gouges nothing"
GOUGE_TOL = 0.005


def mesa(X, Y, c=8.0, radius=4.0, height=4.0):
    """A round mesa whose wall is WALL_DEG at its steepest, rounded at the top and the foot."""
    s = height / (4 * np.tan(np.radians(WALL_DEG)))  # the logistic's steepest slope is height / 4s
    return 1 + height / (1 + np.exp((np.hypot(X - c, Y - c) - radius) / s))


@pytest.fixture(scope="module")
def part():
    return grid_map(mesa, 0, 16, 0, 16, 0.2)


@pytest.fixture(scope="module")
def narrow():
    """8 mm high on a 3 mm radius: the wall of benches/steep.py's 85-degree side, 12 x 12 mm."""
    return grid_map(lambda X, Y: mesa(X, Y, c=6.0, radius=3.0, height=8.0), 0, 12, 0, 12, 0.2)


def brute_tip(sampler, cutter, x, y, rings=400, angles=7200):
    """The drop-cutter by brute force: the highest Z(p + u) - h(|u|) over a fine polar grid."""
    r = np.linspace(0, cutter.radius, rings)[:, None]
    a = np.linspace(0, 2 * np.pi, angles, endpoint=False)[None, :]
    return float(np.max(sampler.z(x + r * np.cos(a), y + r * np.sin(a)) - cutter.profile(r + 0 * a)))


@pytest.mark.parametrize("name", ["ball6", "ball2"])
def test_a_cutter_on_the_floor_beside_the_wall_touches_it_with_its_side(part, name):
    # the axis stands on the flat floor, where no slope is read at the axis, and the
    # contact is on the wall a radius away
    s = Sampler(part, edge_step=0.05)
    c = parse_cutter(name)
    ang = np.radians([10.0, 37.0, 61.0, 100.0, 200.0])
    x = 8 + (4.05 + 0.97 * c.radius) * np.cos(ang)
    y = 8 + (4.05 + 0.97 * c.radius) * np.sin(ang)
    tips = drop_points(s, c, x, y, min(0.1, c.radius / 3))
    exact = np.array([brute_tip(s, c, a, b) for a, b in zip(x, y)])
    # the brute force's own grid is a lower bound; the tip is never lower than it by more
    # than a micron, and never above the brute force by more than its grid's error
    assert np.all(tips >= exact - 0.001), tips - exact
    assert np.all(tips <= exact + 0.01), tips - exact


def test_a_small_ball_finishing_an_85_degree_wall_does_not_gouge_it(narrow):
    # before the drop-cutter met the wall's triangles exactly: 0.21 mm
    tool = Tool(3, parse_cutter("ball2"))
    planned, top = plan_operations(narrow, [Operation("finish", tool, "steep")], scallop=0.05)
    rep, _ = verify_gcode(post_operations(planned, top, "linuxcnc")[0].text, narrow)
    assert rep.gouge <= GOUGE_TOL, (rep.gouge, rep.gouge_at)


def test_waterline_loops_stand_on_their_levels_down_to_the_crease_at_the_foot(narrow):
    # the tip field's lattice is 0.2 mm and bends from the floor onto the wall within a
    # fraction of a node: its straight contours put the lowest loops on the floor or
    # tenths of a millimetre above their level; each point is moved across its loop
    s = Sampler(narrow, edge_step=0.05)
    st = SteepSettings(parse_cutter("ball6"), 0.05)
    field = tip_field(s, st.cutter, st.grid)
    steep, _ = regions(field, st)
    loops, levels, dz = waterlines(s, st, field, steep)
    assert levels >= 2 and dz > 0
    pts = np.vstack(loops)
    z = drop_points(s, st.cutter, pts[:, 0], pts[:, 1], st.resolution)
    own = np.repeat(
        [np.median(z[k : k + len(p)]) for k, p in zip(np.cumsum([0] + [len(p) for p in loops]), loops)],
        [len(p) for p in loops],
    )
    # on the level to well under the scallop asked (0.03 mm at the crease, where the tip
    # rises ~10 mm per mm: 0.003 mm across the loop)
    assert np.max(np.abs(z - own)) <= 0.04, np.max(np.abs(z - own))
    # the lowest loop runs just above the floor (the crease where a cutter resting on the
    # floor meets the wall with its side), not up to a level step above it
    assert own.min() - 1.0 <= FOOT + 0.005, own.min()


def swept_mesa(X, Y):
    """benches/steep.py's mesa: 8 mm high on a 9 mm radius, its wall 60-85 degrees round it
    (85 at +y), a low cap on top, on a floor at z = 1."""
    r, phi = np.hypot(X - 20, Y - 20), np.arctan2(Y - 20, X - 20)
    s = 8.0 / (4 * np.tan(np.radians(72.5 + 12.5 * np.sin(phi))))
    return 1 + 8.0 / (1 + np.exp((r - 9) / s)) + 0.8 * np.clip(1 - (r / 9) ** 2, 0, 1)


def test_on_the_crease_the_wall_behind_the_floors_contact_is_met():
    # axes on the floor ~3.1 mm from the 85-degree wall's middle: the ball rests on the
    # floor and touches the wall with its side. The floor's contact won the search by a
    # hair and only its window was met exactly: 0.005-0.009 mm low at these points.
    s = Sampler(grid_map(swept_mesa, 0, 40, 0, 40, 0.2))
    c = parse_cutter("ball6")
    x = np.array([22.76, 17.42, 25.52, 27.55])
    y = np.array([31.80, 31.83, 30.81, 29.56])
    tips = drop_points(s, c, x, y, 0.02)
    span = int(np.ceil(c.radius / s.dx)) + 1
    exact = facet_contacts(s, c, x, y, x, y, span)  # every triangle under the cutter
    assert np.all(tips >= exact - 1e-6), tips - exact
    assert np.all(tips <= exact + 1e-6), tips - exact


def _every_triangle(s, c, x, y, cells):
    """Reference for facet_contacts: every cell of the window, both planes and all five
    sides met, one point at a time, nothing pruned."""
    from appliance.cam.contact import plane_contact
    from appliance.cam.segments import min_over_segment

    out = np.full(x.size, -np.inf)
    for n, (px, py) in enumerate(zip(x, y)):
        ic, jc = int(np.floor((px - s.x0) / s.dx)), int(np.floor((py - s.y0) / s.dy))
        for j in range(max(jc - cells, 0), min(jc + cells, s.ny - 2) + 1):
            for i in range(max(ic - cells, 0), min(ic + cells, s.nx - 2) + 1):
                z00, z10, z01, z11 = (g[j, i] for g in s.corner_grids)
                x0, y0 = s.x0 + s.dx * i, s.y0 + s.dy * j
                for upper, sx, sy in (
                    (True, (z10 - z00) / s.dx, (z11 - z10) / s.dy),
                    (False, (z11 - z01) / s.dx, (z01 - z00) / s.dy),
                ):
                    ux, uy = plane_contact(c, np.array([sx]), np.array([sy]))
                    u, v = (px + ux[0] - x0) / s.dx, (py + uy[0] - y0) / s.dy
                    if min(u, v) >= 0 and max(u, v) <= 1 and ((u >= v) if upper else (u <= v)):
                        h = c.profile(np.hypot(ux[0], uy[0]))
                        out[n] = max(out[n], z00 + sx * (px + ux[0] - x0) + sy * (py + uy[0] - y0) - h)
                corners = {(0, 0): z00, (1, 0): z10, (0, 1): z01, (1, 1): z11}
                for a, b in (
                    ((0, 0), (1, 0)),
                    ((0, 0), (0, 1)),
                    ((0, 0), (1, 1)),
                    ((1, 0), (1, 1)),
                    ((0, 1), (1, 1)),
                ):
                    ax, ay, za, zb = x0 + a[0] * s.dx, y0 + a[1] * s.dy, corners[a], corners[b]
                    m = min_over_segment(
                        c, px - ax, py - ay, (b[0] - a[0]) * s.dx, (b[1] - a[1]) * s.dy, za - zb, -za
                    )
                    out[n] = max(out[n], -float(m))
    return out


@pytest.mark.parametrize("cutter", ["ball6", "bull6r1"])
@pytest.mark.parametrize("cells", [1, 2])
def test_facet_contacts_prunes_only_what_cannot_rise_above_the_floor(cutter, cells):
    # a coarse map (the daemon's 2 mm cells) of a round 79-degree mesa with a rough top: the window
    # is taken by rows and columns and each side is met by one cell only. Against every
    # triangle met one by one the tips agree wherever they can matter: above the floor given,
    # just under the tip at most points (a small window: contacts on its last row's and
    # column's far sides too)
    rng = np.random.default_rng(3)
    rough = lambda X, Y: 0.4 * np.sin(1.3 * X) * np.cos(0.9 * Y)
    mesa = lambda X, Y: 1 + 6.0 / (1 + np.exp((np.hypot(X - 10, Y - 10) - 5) / 0.3)) + rough(X, Y)
    s = Sampler(grid_map(mesa, 0, 20, 0, 20, 1.6))
    c = parse_cutter(cutter)
    x, y = rng.uniform(2, 18, 400), rng.uniform(2, 18, 400)
    exact = _every_triangle(s, c, x, y, cells)
    assert np.allclose(facet_contacts(s, c, x, y, x, y, cells), exact, atol=1e-9)
    floor = exact - np.where(
        rng.random(x.size) < 0.8, rng.uniform(0, 0.02, x.size), rng.uniform(-0.3, 0.3, x.size)
    )
    pruned = facet_contacts(s, c, x, y, x, y, cells, floor=floor)
    assert np.allclose(np.maximum(pruned, floor), np.maximum(exact, floor), atol=1e-9)
    assert (floor < exact).sum() > 250  # most points still had something to find
