"""The part's edge on the output grid: a finishing program keeps the cells its outline crosses."""

import numpy as np
import pytest

from appliance.cam.sampling import Sampler
from appliance.sim.ideal import ideal_waterlines
from appliance.sim.surfaces import Surface, Tier, rect_sdf
from appliance.surface.edges import with_edge_nodes
from appliance.surface.heightmap import HeightMap
from appliance.surface.reconstruct import GridSpec, reconstruct
from appliance.surface.uncertainty import INTERPOLATED, WALL

# a 10.5 mm block (between two levels: the mid-bracket is exact) whose walls fall 0.3 mm past a node of the 2 mm grid below (x = 20, y = 20)
# and 0.3 mm past the last node inside it on the far sides (x = 60, y = 50)
BLOCK = Surface(
    "block",
    "flat block",
    (20.3, 60.3, 20.3, 50.3),
    (Tier(rect_sdf(20.3, 60.3, 20.3, 50.3), lambda x, y: 10.5 + 0 * x),),
)


def _block_map(lowest=1.0):
    lines = ideal_waterlines(BLOCK, np.arange(11.0, lowest - 0.5, -1.0), 0.1)
    return reconstruct(lines, GridSpec((0.0, 80.0, 0.0, 70.0), n=(41, 36))).heightmap


def test_a_node_within_half_a_cell_past_the_outline_holds_the_edge():
    hm = _block_map()
    X, Y = hm.grid()
    col = {x: int(np.argmin(abs(hm.x - x))) for x in (18.0, 20.0, 60.0, 62.0)}
    row = int(np.argmin(abs(hm.y - 36.0)))
    # x = 20 lies 0.3 mm outside the wall: it holds the top, on the wall, marked uncertain
    assert abs(hm.z[row, col[20.0]] - 10.5) < 0.2, hm.z[row, col[20.0]]
    assert hm.source[row, col[20.0]] == WALL and hm.sigma[row, col[20.0]] > 1.0
    # 2.3 mm and 1.7 mm outside (more than half a cell): off the part, as before
    assert np.isnan(hm.z[row, col[18.0]]) and np.isnan(hm.z[row, col[62.0]])
    assert abs(hm.z[row, col[60.0]] - 10.5) < 0.2
    # nothing more than half a cell from the block has a height
    far = (np.maximum(np.maximum(20.3 - X, X - 60.3), np.maximum(20.3 - Y, Y - 50.3))) > 1.0
    assert not np.isfinite(hm.z[far]).any()


def test_the_program_s_surface_keeps_the_part_out_to_its_outline():
    # the CAM mills a cell as part only when all its corners have a height: without the edge
    # nodes, the strip from x = 20.3 to 22 of the block was the base, a 10 mm gouge
    s = Sampler(_block_map())
    inside_edge = s.z(np.array([20.5, 21.5, 40.0]), np.array([36.0, 36.0, 20.6]))
    assert np.all(np.abs(inside_edge - 10.5) < 0.2), inside_edge
    # and past the outline by more than a cell the cutter goes down to the base
    assert s.z(np.array([17.0]), np.array([36.0]))[0] == 0.0


def test_a_scan_stopped_above_the_base_keeps_the_edge_where_its_lowest_frame_ran_along_a_wall():
    # scanned down to 6 mm only, as the dissertation scanned sample 3's 45 mm sides to 24 mm:
    # the lowest waterline runs along the walls, which go on straight down
    hm = _block_map(lowest=6.0)
    row = int(np.argmin(abs(hm.y - 36.0)))
    at_20 = int(np.argmin(abs(hm.x - 20.0)))
    assert abs(hm.z[row, at_20] - 10.5) < 0.2, hm.z[row, at_20]


def _edge_row_behind_a_wall():
    # a 12 mm top on x = 0..2, its edge nodes at x = 3; the fit carried the top on past the rim
    x, y = np.arange(5.0), np.arange(3.0)
    z = np.full((3, 5), np.nan)
    z[:, :3] = 12.0
    sigma = np.where(np.isfinite(z), 0.05, np.nan)
    source = np.where(np.isfinite(z), INTERPOLATED, -1).astype(np.int8)
    edge = np.zeros(z.shape, bool)
    edge[:, 3] = True
    ray = np.full(z.shape, np.inf)
    ray[0, 3], ray[1, 3] = 9.8, 20.0  # row 2: no ray over it, a wall the camera saw
    return x, y, with_edge_nodes(z, sigma, source, edge, WALL, np.full(z.shape, 13.0), ray)


def test_an_edge_node_behind_a_hidden_wall_is_the_middle_between_the_base_and_the_ray():
    _, _, (z, sigma, source) = _edge_row_behind_a_wall()
    assert z[0, 3] == pytest.approx(4.9) and sigma[0, 3] == pytest.approx(np.hypot(0.05, 9.8 / np.sqrt(12)))
    # a ray higher than the top it is next to: the middle under the top
    assert z[1, 3] == pytest.approx(6.0)
    # no ray: the fit continued out, held at the top
    assert z[2, 3] == pytest.approx(12.0)
    assert (source[:, 3] == WALL).all() and np.isnan(z[:, 4]).all()


def test_the_program_keeps_the_wall_s_top_edge_where_the_map_says_mid_wall():
    x, y, (z, sigma, source) = _edge_row_behind_a_wall()
    hm = HeightMap(x, y, z, sigma, source)
    s = Sampler(hm)
    # the wall's top edge lies somewhere in the cell from x = 2 to 3: the cutter stays on top
    assert s.z(np.array([2.5, 2.99]), np.array([0.5, 0.5])) == pytest.approx([12.0, 12.0])
    assert hm.z[0, 3] == pytest.approx(4.9)  # the map keeps what the frames say
    # an outline node not on a wall (a slope run down to the base) is milled as it is
    source[:, 3] = INTERPOLATED
    assert Sampler(HeightMap(x, y, z, sigma, source)).z(np.array([2.99]), np.array([0.5]))[
        0
    ] == pytest.approx(5.45, abs=0.1)
