"""The per-cell uncertainty map: what each cell says about itself, in the csv, the report
and the G-code header; old x,y,z files keep working."""

import os
import re
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam.cutters import parse_cutter
from appliance.cam.gcodeparse import parse_gcode
from appliance.cam.jobs import finishing_gcode
from appliance.cam.zigzag import FinishSettings
from appliance.cli import main
from appliance.outputs import read_heightmap_csv, write_heightmap_csv
from appliance.report import uncertainty_markdown
from appliance.sim.ideal import ideal_waterlines
from appliance.sim.surfaces import Surface, Tier, disc_sdf
from appliance.surface.base import stand_on_base
from appliance.surface.confidence import header_notes, low_confidence_regions
from appliance.surface.heightmap import HeightMap
from appliance.surface.reconstruct import GridSpec, reconstruct
from appliance.surface.uncertainty import (
    CLAMPED,
    EXTRAPOLATED,
    SOURCES,
    _inradius,
    source_code,
)

# a paraboloid dome on a disc, 20 mm at its top (50, 50)
DOME = Surface(
    "dome",
    "paraboloid",
    (10.0, 90.0, 10.0, 90.0),
    (Tier(disc_sdf(50, 50, 40), lambda x, y: 20 - 0.01 * ((x - 50) ** 2 + (y - 50) ** 2)),),
)
GRID = GridSpec((10, 90, 10, 90), n=(41, 41))


def dome_map(step_mm):
    levels = np.arange(20.0 - step_mm / 2, 1.0, -step_mm)  # the top lies between two frames
    return reconstruct(ideal_waterlines(DOME, levels, resolution_mm=0.2), GRID).heightmap


@pytest.fixture(scope="module")
def dome():
    return dome_map(1.0)


def test_every_cell_on_the_part_has_a_source_and_an_uncertainty(dome):
    on = dome.on_part
    assert np.all(dome.source[on] >= 0) and np.all(dome.source[~on] == -1)
    assert np.all(np.isfinite(dome.sigma[on])) and np.all(dome.sigma[on] >= 0)
    # most of a smooth dome is on or between the waterlines and sure to well under 0.1 mm
    names = {SOURCES[k] for k in np.unique(dome.source[on])}
    assert {"seen", "interpolated"} <= names
    assert np.median(dome.sigma[on]) < 0.1


def test_the_top_above_the_highest_frame_is_extrapolated_and_less_sure(dome):
    j, i = 20, 20  # (50, 50): 0.5 mm above the top frame
    assert dome.source[j, i] == EXTRAPOLATED
    assert dome.sigma[j, i] > 3 * np.median(dome.sigma[dome.on_part])


def test_a_top_region_reaches_in_as_far_as_its_middle_is_from_the_waterlines():
    # the extrapolated top's uncertainty grows towards its middle: a disc's middle is its
    # radius in, a thin ring's (a ridge's crest) only its half-width, whatever its area
    y, x = np.mgrid[-50:51, -50:51] * 0.5
    r = np.hypot(x, y)
    disc, to_disc_edge = r < 10, 10 - r
    ring, to_ring_edge = np.abs(r - 18) < 2, 2 - np.abs(r - 18)
    for top, d, reach in ((disc, to_disc_edge, 10.0), (ring, to_ring_edge, 2.0)):
        got = _inradius(top, np.where(top, d, 0.0), 0.5)
        assert got[top].min() == got[top].max() == pytest.approx(reach, abs=0.5)


def test_uncertainty_grows_with_the_level_step():
    medians = []
    for step in (0.5, 2.0):
        hm = dome_map(step)
        inner = hm.on_part & ~np.isin(hm.source, [source_code("wall")])
        medians.append(float(np.mean(hm.sigma[inner])))
    assert medians[1] > 1.5 * medians[0], medians


def test_a_clamped_cell_says_so_and_is_at_least_its_dip_uncertain():
    hm = grid_map(lambda X, Y: 2 + 0 * X, 0, 10, 0, 10, 1.0)
    hm.sigma = np.full(hm.z.shape, 0.01)
    hm.source = np.full(hm.z.shape, source_code("interpolated"), np.int8)
    hm.z[3, 4] = -0.3
    fixed, fix = stand_on_base(hm)
    assert fix.clamped_cells == 1
    assert fixed.source[3, 4] == CLAMPED and fixed.z[3, 4] == 0.0
    assert fixed.sigma[3, 4] >= 0.3
    assert fixed.source[3, 5] == source_code("interpolated")


def test_a_filled_gap_says_so():
    hm = grid_map(lambda X, Y: 2 + 0.1 * X, 0, 10, 0, 10, 1.0)
    hm.sigma = np.full(hm.z.shape, 0.01)
    hm.source = np.zeros(hm.z.shape, np.int8)
    hm.z[5, 5] = np.nan
    fixed, fix = stand_on_base(hm)
    assert fix.filled_cells == 1 and SOURCES[fixed.source[5, 5]] == "filled"
    assert fixed.sigma[5, 5] > 0.01  # no better known than the heights around it


def test_the_csv_carries_source_and_uncertainty_after_x_y_z(tmp_path, dome):
    path = tmp_path / "heightmap.csv"
    write_heightmap_csv(path, dome)
    lines = path.read_text().splitlines()
    assert lines[0] == "x,y,z,source,uncertainty_mm"
    assert re.fullmatch(r"-?[\d.]+,-?[\d.]+,-?[\d.]+,(" + "|".join(SOURCES) + r"),[\d.]+", lines[1])
    back = read_heightmap_csv(path)
    on = dome.on_part
    assert np.array_equal(back.source[on], dome.source[on])
    assert np.allclose(back.sigma[on], dome.sigma[on], atol=1e-4)
    assert np.allclose(back.z[on], dome.z[on], atol=1e-4)


def test_an_old_three_column_csv_still_loads_and_mills(tmp_path):
    path = tmp_path / "old.csv"
    rows = [f"{x},{y},{5 + 0.05 * x:.4f}" for y in range(0, 11) for x in range(0, 13)]
    path.write_text("x,y,z\n" + "\n".join(rows) + "\n")
    hm = read_heightmap_csv(path)
    assert hm.sigma is None and hm.source is None and hm.z.shape == (11, 13)
    assert main(["toolpath", str(path), "-o", str(tmp_path / "old.gcode"), "--scallop", "0.05"]) == 0
    assert "low confidence" not in (tmp_path / "old.gcode").read_text()


@pytest.mark.parametrize(
    "line, says",
    [
        ("1,2,3,wobbly,0.1", "unknown source 'wobbly'"),
        ("1,2,3,seen,-0.1", "uncertainty_mm must be a finite number >= 0"),
        ("1,2,3,seen", "has 4 values, the header names 5"),
    ],
)
def test_bad_extra_columns_are_named(tmp_path, line, says):
    from appliance.errors import InkSliceError

    path = tmp_path / "bad.csv"
    path.write_text("x,y,z,source,uncertainty_mm\n0,0,1,seen,0.01\n" + line + "\n")
    with pytest.raises(InkSliceError, match=re.escape(says)):
        read_heightmap_csv(path)


def _unsure_block():
    """A dish, sure everywhere but for a 4 x 3 mm patch at x 12..16, y 4..7 (0.4 mm)."""
    hm = grid_map(lambda X, Y: 6 + 0.02 * ((X - 10) ** 2 + (Y - 8) ** 2), 0, 20, 0, 16, 1.0)
    X, Y = hm.grid()
    patch = (X >= 12) & (X <= 16) & (Y >= 4) & (Y <= 7)
    hm.sigma = np.where(patch, 0.4, 0.02)
    hm.source = np.where(patch, source_code("wall"), source_code("seen")).astype(np.int8)
    return hm, patch


def test_low_confidence_regions_are_boxed_in_mm():
    hm, patch = _unsure_block()
    (r,) = low_confidence_regions(hm, 0.1)
    assert (r.xmin, r.xmax, r.ymin, r.ymax) == (11.5, 16.5, 3.5, 7.5)
    assert r.cells == patch.sum() and r.source == "wall" and r.worst_mm == pytest.approx(0.4)
    assert r.share == pytest.approx(patch.sum() / patch.size)
    assert low_confidence_regions(hm, 0.5) == []


def test_the_gcode_header_lists_the_low_confidence_region_and_stays_valid(tmp_path):
    hm, patch = _unsure_block()
    text = finishing_gcode(hm, FinishSettings(parse_cutter("ball6"), scallop=0.05)).text
    head = [line for line in text.splitlines() if line.startswith("(")]
    assert any(
        "low confidence 1: X 11.5..16.5 Y 3.5..7.5 mm" in line and "mostly wall" in line for line in head
    )
    assert any(f"{100 * patch.sum() / patch.size:.1f} % of the part in 1 region" in line for line in head)
    assert not any("low confidence" in line for line in text.splitlines() if not line.startswith("("))
    parse_gcode(text, "header")  # still our own parser's G-code
    rs274 = "/usr/bin/rs274"
    if os.path.exists(rs274):
        (tmp_path / "p.ngc").write_text(text)
        r = subprocess.run(
            [rs274, "-g", str(tmp_path / "p.ngc"), str(tmp_path / "out.txt")],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 0, r.stdout + r.stderr


def test_the_part_s_edge_is_told_apart_from_the_regions_inside():
    """Edge nodes stand anywhere from the base to the wall's height (up to several mm
    uncertain). Joined through them, every unsure patch touching the edge made one region
    of the whole part; the header names the patch, and the edge on a line of its own."""
    hm, patch = _unsure_block()
    X, Y = hm.grid()
    patch |= (X >= 12) & (X <= 19) & (Y >= 4) & (Y <= 7)  # out to the cells next to the edge
    rim = (X == X.min()) | (X == X.max()) | (Y == Y.min()) | (Y == Y.max())
    hm.sigma = np.where(rim, 2.5, np.where(patch, 0.4, 0.02))
    found = low_confidence_regions(hm, 0.1)
    assert [r.edge for r in found] == [False, True]
    inside, edge = found
    assert (inside.xmin, inside.xmax, inside.ymin, inside.ymax) == (11.5, 19.5, 3.5, 7.5)
    assert inside.worst_mm == pytest.approx(0.4) and inside.cells == patch.sum()
    assert edge.cells == rim.sum() and edge.worst_mm == pytest.approx(2.5)
    head = header_notes(hm, 0.1)
    assert "in 1 region(s) and at its edge" in head[0]
    assert head[1].startswith("low confidence 1: X 11.5..19.5 Y 3.5..7.5 mm") and "up to 0.40 mm" in head[1]
    assert head[2].startswith("low confidence: the part's edge, 72 cells round its outline")
    assert "up to 2.50 mm" in head[2] and len(head) == 3
    # and says the program does not follow those cells down where they are walls (cam/sampling.py)
    assert head[2].endswith("the program keeps the top edge over the cells on a wall")
    # the report's table: the patch numbered, the edge as its own last row
    md = "\n".join(uncertainty_markdown(SimpleNamespace(heightmap=hm, diagnostics={})))
    assert "in 1 region(s) and at its edge" in md
    assert "| 1 | 11.5 .. 19.5 | 3.5 .. 7.5 |" in md
    assert re.search(r"\| edge \| all round \| \| [0-9.]+ \| 2\.50 \|", md)


def test_a_sure_map_says_so_and_a_map_without_uncertainty_says_nothing():
    hm, _ = _unsure_block()
    hm.sigma[:] = 0.02
    assert header_notes(hm, 0.1) == ["confidence: every cell of the height map within 0.1 mm"]
    assert header_notes(HeightMap(hm.x, hm.y, hm.z), 0.1) == []


def test_cells_under_an_occluding_face_are_labelled_occluded_and_a_step_unsure():
    from appliance.surface.reconstruct import _occluded_cells
    from appliance.surface.slices import make_slice

    src = np.full((4, 5), source_code("interpolated"), np.int8)
    src[0, 0] = -1  # off the part stays off
    sig = np.full((4, 5), 0.01)
    hidden = np.zeros((4, 5), bool)
    hidden[:2, :2] = True
    slices = [make_slice(L, [[(0, 0), (1, 0), (1, 1)]]) for L in (10.0, 9.0, 8.0)]
    src2, sig2 = _occluded_cells(src, sig, hidden, slices)
    assert [SOURCES[k] for k in src2[:2, :2].ravel() if k >= 0] == ["occluded"] * 3 and src2[0, 0] == -1
    assert sig2[1, 1] == pytest.approx(1 / np.sqrt(12)) and sig2[3, 4] == 0.01
    assert _occluded_cells(src, sig, 7, slices)[0] is src  # a count, not a mask: nothing to mark


def _ridge_evidence(rise):
    """A long ridge along y, its crest 10 mm high at x = 50 and 45 deg flanks, scanned at
    levels 9.5, 8.5, ... with the given meniscus correction per node (capillary 2.5 mm)."""
    from appliance.surface.lattice import Lattice
    from appliance.surface.uncertainty import CellEvidence

    lat = Lattice(np.arange(30.0, 70.01, 0.5), np.arange(0.0, 20.01, 0.5))
    X, _ = np.meshgrid(lat.x, lat.y)
    z = 10.0 - np.abs(X - 50.0)
    lv = np.arange(9.5, -10.0, -1.0)
    exposed = np.stack([z > L for L in lv])
    first = np.argmax(exposed, axis=0)
    ev = CellEvidence(lat, z, z, first, z > lv[-1], [], exposed, 0.05, None, rise(X), 2.5)
    return ev, lv, X


def test_a_rise_is_unsure_just_below_the_top_it_came_out_with():
    # the model lifts the flanks' contact lines 1.5 mm, as on an open face; next to the
    # crest the face ends above the contact line before the ink could climb that high
    from appliance.surface.uncertainty import _shared_meniscus

    ev, lv, X = _ridge_evidence(lambda X: np.full(X.shape, 1.5))
    u = _shared_meniscus(ev, lv)
    crest, far_down = np.abs(X - 50) < 1, (np.abs(X - 50) > 8) & ev.footprint
    assert u[crest].min() > 0.1  # a tenth of the rise or more: low confidence
    assert u[far_down].max() < 0.1 * 1.5 * np.exp(-7 / 2.5) + 1e-9  # the face went on: fades


def test_a_shelf_beside_a_wall_shares_its_meniscus():
    # the flanks rise 2 mm but a flat shelf (no rise of its own) starts 5 mm out: within a
    # capillary length of the flank the shelf's contact line is the flank's meniscus too
    from appliance.surface.uncertainty import _shared_meniscus

    ev, lv, X = _ridge_evidence(lambda X: np.where(np.abs(X - 50) < 5, 2.0, 0.0))
    u = _shared_meniscus(ev, lv)
    near, far = (np.abs(np.abs(X - 50) - 6) < 0.3), np.abs(X - 50) > 9
    assert u[near].min() == pytest.approx(0.2, abs=0.01)  # a tenth of what the wall rises
    assert u[far & ev.footprint].max() == pytest.approx(0.0)
