"""Several tools in one job: the tool table, the operations, tool changes a
controller accepts (rs274 for LinuxCNC/Mach3/Fanuc, our GRBL and Fanuc rules),
one file per tool for GRBL, and a verification of the whole job."""

import numpy as np
import pytest
from cam_helpers import grid_map
from test_cam_program import _rs274

from appliance.cam.cutters import parse_cutter
from appliance.cam.dialects import check_fanuc, check_grbl
from appliance.cam.gcodeparse import parse_gcode
from appliance.cam.jobs import verify_gcode
from appliance.cam.operations import parse_operations, plan_operations, post_operations
from appliance.cam.posts import render
from appliance.cam.program import build_program
from appliance.cam.tools import DEFAULT_TOOL_TABLE, default_tools, parse_tool_table
from appliance.errors import SettingError


def mesa(X, Y):
    # a round mesa 6 mm high on a floor, walls up to 72 degrees, a concave foot a
    # 6 mm ball cannot reach: 30 x 30 mm, small enough to plan three tools quickly
    r = np.hypot(X - 15, Y - 15)
    return 1 + 6 / (1 + np.exp((r - 7) / 0.5))


@pytest.fixture(scope="module")
def job():
    hm = grid_map(mesa, 0, 30, 0, 30, 0.25)
    ops = parse_operations("rough T1, finish T2 steep, rest T3", default_tools())
    planned, top = plan_operations(hm, ops, scallop=0.05)
    return hm, planned, top


def test_tool_table_names_the_bad_entry():
    table = parse_tool_table(DEFAULT_TOOL_TABLE)
    assert [t.name for t in table.values()] == ["flat6", "ball6", "ball2"]
    bad = [dict(DEFAULT_TOOL_TABLE[0]), dict(DEFAULT_TOOL_TABLE[0])]
    with pytest.raises(SettingError, match="tool number 1 is listed twice"):
        parse_tool_table(bad)
    with pytest.raises(SettingError, match="T2.*type must be one of"):
        parse_tool_table([{**DEFAULT_TOOL_TABLE[1], "type": "drill"}])
    with pytest.raises(SettingError, match="T4.*corner radius must be less"):
        parse_tool_table([{"number": 4, "type": "bull", "diameter_mm": 6, "corner_radius_mm": 3}])
    with pytest.raises(SettingError, match="unknown material"):
        parse_tool_table([{**DEFAULT_TOOL_TABLE[1], "feeds": {"steel": {"feed_mm_min": 100}}}])


def test_a_tools_own_feeds_win_over_the_table():
    t = parse_tool_table([{**DEFAULT_TOOL_TABLE[1], "feeds": {"wax": {"feed_mm_min": 700, "rpm": 9000}}}])[2]
    c = t.conditions("wax")
    assert (c.feed, c.rpm) == (700, 9000)
    assert t.conditions("wood").feed != 700  # no entry: the feeds table's figure


def test_operations_are_checked_against_the_table():
    tools = default_tools()
    with pytest.raises(SettingError, match="tool 7 is not in the tool table"):
        parse_operations("finish T7", tools)
    with pytest.raises(SettingError, match="rest machining needs a finish before it"):
        parse_operations("rough T1, rest T3", tools)
    with pytest.raises(SettingError, match="must be smaller"):
        parse_operations("finish T3, rest T2", tools)
    ops = parse_operations("rough T1, finish T2 steep, rest T3", tools)
    assert [(o.kind, o.tool.number, o.strategy) for o in ops] == [
        ("rough", 1, "zigzag"),
        ("finish", 2, "steep"),
        ("rest", 3, "steep"),
    ]


@pytest.mark.parametrize("dialect", ["linuxcnc", "mach3", "fanuc"])
def test_tool_changing_controllers_get_one_program_with_tn_m6_and_g43(tmp_path, job, dialect):
    hm, planned, top = job
    posted = post_operations(planned, top, dialect, job="demo")
    assert len(posted) == 1
    p = posted[0]
    assert p.name == f"demo-rough-flat6-finish-ball6-rest-ball2-{dialect}.nc"
    r = _rs274(tmp_path, p.text)
    assert r.returncode == 0, r.stdout + r.stderr
    out = (tmp_path / "out.txt").read_text()
    assert [int(s) for s in __import__("re").findall(r"SELECT_TOOL\((\d+)\)", out)] == [1, 2, 3]
    assert out.count("USE_TOOL_LENGTH_OFFSET") >= 3
    body = [l.split(" ", 1)[1] if l.startswith("N") else l for l in p.text.splitlines()]
    for n in (1, 2, 3):
        k = body.index(f"T{n} M6")
        assert body[k + 1] == f"G43 H{n}" and body[k + 2].startswith("M3 S")
    if dialect == "fanuc":
        assert check_fanuc(p.text) == []
    parsed = parse_gcode(p.text)
    assert sorted(set(parsed.tool.tolist())) == [1, 2, 3]  # no move before the first change


def test_grbl_gets_one_file_per_tool_each_opening_with_a_pause(job):
    hm, planned, top = job
    posted = post_operations(planned, top, "grbl", job="demo")
    assert [p.name for p in posted] == [
        "demo-rough-flat6-grbl.nc",
        "demo-finish-ball6-grbl.nc",
        "demo-rest-ball2-grbl.nc",
    ]
    for p, n in zip(posted, (1, 2, 3)):
        lines = p.text.splitlines()
        m0 = lines.index("M0")
        assert m0 >= 1 and all(l.startswith("(") for l in lines[:m0]) and f"T{n}" in " ".join(lines[:m0])
        assert check_grbl(p.text) == []
        assert "M6" not in p.text


def test_the_whole_job_leaves_no_more_than_the_finishing_tool_and_gouges_nothing(job):
    hm, planned, top = job
    text = post_operations(planned, top, "linuxcnc", job="demo")[0].text
    whole, info = verify_gcode(text, hm)
    fin = planned[1]
    tool = fin.op.tool
    prog = build_program(fin.runs, tool.cutter, tool.conditions("wax"), top, "finish alone")
    alone, _ = verify_gcode(render(prog, "linuxcnc", 1.0), hm)
    cell = 0.1 * 0.1
    left = lambda rep: float(np.sum(np.maximum(rep.deviation, 0)[rep.part]) * cell)
    assert info["cutter"].startswith("T1 flat D6.000") and "T3 ball D2.000" in info["cutter"]
    assert whole.crashes == 0
    # the drop-cutter's own accuracy on a 72-degree wall of a 0.25 mm map: verify's
    # default --max-gouge (0.01) plus its lattice
    assert whole.gouge <= 0.012 and alone.gouge <= 0.012
    assert left(whole) <= left(alone)
    assert whole.uncut_area <= alone.uncut_area
    # the rest tool reaches into the foot the 6 mm ball could not
    assert whole.uncut_area < 0.2 * alone.uncut_area


def test_verify_refuses_a_change_to_a_tool_the_header_does_not_describe(job):
    hm, planned, top = job
    text = post_operations(planned, top, "linuxcnc", job="demo")[0].text
    text = text.replace("(inkslice tool 3: ball D2.000 CR1.000 FL16.0)\n", "")
    with pytest.raises(Exception, match="changes to tool 3"):
        verify_gcode(text, hm)


def test_the_settings_keep_the_tool_table_and_operations_checked_together():
    from appliance.cam.tools import parse_tool_text
    from appliance.daemon import settings as S

    tools = parse_tool_text(S.DEFAULTS["tool_table"])
    assert [t.name for t in tools.values()] == ["flat6", "ball6", "ball2"]
    assert len(parse_operations(S.DEFAULTS["operations"], tools)) == 3
    own = parse_tool_text("T5 bull D6 CR1 FL30 wax:F900/P300/S12000")[5]
    assert own.cutter.name == "bull6r1" and own.conditions("wax").feed == 900
    with pytest.raises(SettingError, match="operations: 'finish T9': tool 9 is not in the tool table"):
        S.validate(S.DEFAULTS, {"operations": "finish T9"})
    with pytest.raises(SettingError, match="tool_table: 'T2 drill D3'"):
        S.validate(S.DEFAULTS, {"tool_table": "T2 drill D3"})
    with pytest.raises(SettingError, match="steep_angle_deg"):
        S.validate(S.DEFAULTS, {"steep_angle_deg": 90})
    assert S.validate(S.DEFAULTS, {"tool_table": "T1 flat D8; T2 ball D6; T3 ball D3"})[
        "tool_table"
    ].startswith("T1 flat D8")


def test_steep_walls_get_constant_z_passes_and_the_two_regions_cover_the_part():
    from appliance.cam import waterline as W
    from appliance.cam.sampling import Sampler

    hm = grid_map(lambda X, Y: 1 + 5 / (1 + np.exp((np.hypot(X - 10, Y - 10) - 5) / 0.4)), 0, 20, 0, 20, 0.25)
    s = Sampler(hm, edge_step=0.05)
    st = W.SteepSettings(parse_cutter("ball4"), scallop=0.05)
    field = W.tip_field(s, st.cutter, st.grid)
    steep, shallow = W.regions(field, st)
    on = np.isfinite(field.tip)
    assert (steep | shallow)[on].all()  # no gap
    assert (steep & shallow).sum() > 0.05 * steep.sum()  # and a seam cut by both
    p = W.plan(s, st, field=field)
    assert p.levels >= 5 and p.waterline_runs >= p.levels - 2 and p.zigzag_runs > 0
    # a waterline holds its height: each run within half a level step (the drop, not the contour, sets Z)
    for r in p.runs[p.zigzag_runs :]:
        assert np.ptp(r[:, 2]) < p.level_step / 2
    # the level step holds the vertical scallop on the steepest wall: (dz / sin t)^2 / (8 r cos t) = h
    t = np.radians(80)
    dz = W.level_step(st.cutter, 0.05, 80)
    assert (dz / np.sin(t)) ** 2 / (8 * 2 * np.cos(t)) == pytest.approx(0.05)
