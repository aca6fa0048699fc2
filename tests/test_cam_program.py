"""Programs a controller accepts: motion hygiene, dialects (rs274, GRBL and Fanuc rules),
machine limits, boundary handling, roughing, parsing back, bad input, the commands."""

import re
import shutil
import subprocess

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam.cutters import parse_cutter
from appliance.cam.dialects import check_fanuc, check_grbl
from appliance.cam.gcodeparse import parse_gcode
from appliance.cam.jobs import finishing_gcode, roughing_gcode, verify_gcode
from appliance.cam.limits import Machine
from appliance.cam.roughing import RoughSettings
from appliance.cam.sampling import Sampler
from appliance.cam.seed import seed_gcode
from appliance.cam.zigzag import FinishSettings
from appliance.errors import InkSliceError, SettingError
from appliance.sim import surfaces

RS274 = "/usr/bin/rs274"


def bowl():
    # a dish: concave, 20 x 16 mm (small, so the many programs below stay quick)
    return grid_map(lambda X, Y: 6 + 0.02 * ((X - 10) ** 2 + (Y - 8) ** 2), 0, 20, 0, 16, 1.0)


def finish(hm=None, **kw):
    kw.setdefault("scallop", 0.05)
    cutter = parse_cutter(kw.pop("cutter", "ball6"))
    job_kw = {
        k: kw.pop(k)
        for k in list(kw)
        if k in ("dialect", "machine", "feed", "plunge", "z_offset", "material", "rpm", "clearance")
    }
    return finishing_gcode(hm if hm is not None else bowl(), FinishSettings(cutter, **kw), **job_kw)


@pytest.fixture(scope="module")
def linuxcnc_text():
    return finish().text


def test_motion_hygiene(linuxcnc_text):
    lines = [l for l in linuxcnc_text.splitlines() if not l.startswith("(")]
    p = parse_gcode(linuxcnc_text)
    safe = p.xyz[0, 2]
    assert p.kind[0] == 0 and re.fullmatch(
        r"G0 Z[\d.]+", lines[lines.index(next(l for l in lines if l.startswith("G0")))]
    )
    assert safe > np.nanmax(bowl().z)  # above the part's top
    # rapids only at the safe height, or straight up out of a cut
    for k in np.flatnonzero(p.kind == 0)[1:]:
        prev = p.xyz[k - 1]
        assert p.xyz[k, 2] == pytest.approx(safe) and (
            np.allclose(prev[:2], p.xyz[k, :2]) or prev[2] == pytest.approx(safe)
        )
    # every descent is a G1 at the plunge feed, the cuts at the cutting feed
    first_g1 = next(i for i, l in enumerate(lines) if l.startswith("G1"))
    assert "F" in lines[first_g1] and any(l.startswith("M3 S") for l in lines[:first_g1])
    plunge, cut = np.unique(p.feed[p.kind == 1])[[0, -1]]
    assert plunge < cut
    assert lines[-2:] == ["M5", "M30"]
    assert "program Z = height above the base top + 0.000 mm work offset" in linuxcnc_text
    assert "estimated run time" in linuxcnc_text


def _rs274(tmp_path, text):
    assert shutil.which(RS274) or __import__("os").path.exists(RS274), (
        "rs274 missing: scripts/setup.sh --test installs linuxcnc-uspace"
    )
    src = tmp_path / "p.ngc"
    src.write_text(text)
    r = subprocess.run(
        [RS274, "-g", str(src), str(tmp_path / "out.txt")],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return r


@pytest.mark.parametrize("dialect", ["linuxcnc", "mach3"])
def test_linuxcnc_compatible_dialects_pass_rs274(tmp_path, dialect):
    r = _rs274(tmp_path, finish(dialect=dialect).text)
    assert r.returncode == 0, r.stdout + r.stderr


def test_rs274_rejects_what_it_should(tmp_path):
    # the checker is real: G1 before any F fails
    assert _rs274(tmp_path, "G21 G90\nG1 X1 Y1\nM30\n").returncode != 0


def test_grbl_and_fanuc_rules():
    g = finish(dialect="grbl").text
    assert check_grbl(g) == []
    assert max(len(l) for l in g.splitlines()) <= 80
    assert check_grbl("N10 G64 X1.5\nM6\n")  # catches N words, G64, M6, 1 decimal
    f = finish(dialect="fanuc").text
    assert check_fanuc(f) == []
    assert f.splitlines()[0] == "%" and f.splitlines()[1] == "O0001"
    assert check_fanuc("%\nO0001\nG1 X10 F100\n%\n")  # X10 without a point is 10 microns there
    # all dialects describe the same moves
    a = parse_gcode(g).xyz
    b = parse_gcode(f).xyz
    assert a.shape == b.shape and np.nanmax(np.abs(a - b)) < 0.0011


def test_dissertation_dialect_and_its_gouge():
    hm = bowl()
    text = finish(hm, dialect="dissertation").text
    assert text == seed_gcode(hm)
    rep, _ = verify_gcode(text, hm, cutter="ball6", z_zero=float(np.nanmax(hm.z)), resolution=0.1)
    ours, _ = verify_gcode(finish(hm).text, hm, resolution=0.1)
    assert rep.gouge > 0.1  # surface points as tool tips: the ball digs in
    assert ours.gouge <= 0.005


def test_parser_round_trip_and_errors():
    text = finish(dialect="linuxcnc").text
    p = parse_gcode(text)
    assert p.meta("inkslice cutter").startswith("ball D6.000")
    assert np.all(np.isfinite(p.xyz[1:]))
    inch = parse_gcode("G20 G90\nG0 X1 Y2 Z3\n")
    assert np.allclose(inch.xyz[0], [25.4, 50.8, 76.2])
    rel = parse_gcode("G90 G0 X1 Y1 Z1\nG91 G1 X1 F100\n")
    assert np.allclose(rel.xyz[1], [2, 1, 1])
    for bad, what in (
        ("G1 X1\n", "no feed"),
        ("G2 X1 Y1 I1 F10\n", "arcs"),
        ("G0 X1 Q5\n", "Q5"),
        ("G0 X1 (open\n", "parenthesis"),
        ("M30\nG0 X1\n", "after the program end"),
    ):
        with pytest.raises(InkSliceError, match=what):
            parse_gcode(bad)


def test_envelope_is_refused_not_clipped():
    m = Machine(travel=((-10, 15), (-10, 210), (-5, 150)))
    with pytest.raises(SettingError, match=r"X travel -10..15 mm by 5\.000 mm"):
        finish(machine=m, margin=0.0)  # the part alone: 5 mm past X 15
    with pytest.raises(SettingError, match="Z travel"):
        finish(machine=Machine(travel=((-10, 300), (-10, 300), (-5, 12))))
    # a work offset moves the program, and can push it out
    with pytest.raises(SettingError, match="Z travel"):
        finish(z_offset=140.0)


def test_feed_limits_slow_moves_down():
    m = Machine(max_feed=(3000.0, 3000.0, 200.0))
    text = finish(machine=m, feed=1500.0, plunge=600.0).text
    p = parse_gcode(text)
    start = p.xyz[:-1]
    d = np.abs(p.xyz[1:] - start)
    L = np.linalg.norm(d, axis=1)
    feed = p.feed[1:]
    vz = np.where(L > 0, feed * d[:, 2] / np.where(L > 0, L, 1), 0)
    g1 = p.kind[1:] == 1
    assert np.all(vz[g1] <= 200.0 * 1.02)  # the printed coordinates are rounded
    assert np.nanmax(feed) == 1500.0


def test_boundary_margin():
    hm = bowl()
    s = Sampler(hm)
    for margin in (0.0, 2.0):
        p = parse_gcode(finish(hm, margin=margin).text)
        cut = p.kind == 1
        dist = s.part_distance(p.xyz[cut, 0], p.xyz[cut, 1])
        assert dist.max() <= margin + 1e-6
        if margin:
            assert dist.max() > margin - 0.2  # it does use the margin
    with pytest.raises(SettingError, match="more than the cutter radius"):
        finish(hm, margin=3.5)


def test_a_footprint_with_a_bay_is_cut_in_runs():
    # an L-shaped part: passes that cross the bay lift, rapid at safe height and plunge again
    hm = grid_map(lambda X, Y: 5 + 0.05 * X, 0, 30, 0, 30, 1.0)
    hm.z[(hm.y[:, None] > 15) & (hm.x[None, :] > 15)] = np.nan
    p = parse_gcode(finish(hm, margin=0.0).text)
    s = Sampler(hm)
    cut = p.kind == 1
    assert s.part_distance(p.xyz[cut, 0], p.xyz[cut, 1]).max() <= 1e-6
    rep, _ = verify_gcode(finish(hm).text, hm, resolution=0.1)
    assert rep.gouge <= 0.005 and rep.crashes == 0


def test_roughing_takes_the_block_down_to_the_allowance():
    hm = bowl()
    top = float(np.nanmax(hm.z)) + 2
    job = roughing_gcode(hm, RoughSettings(parse_cutter("flat6"), top, stepdown=1.5, leave=0.3))
    assert (
        check_grbl(roughing_gcode(hm, RoughSettings(parse_cutter("flat6"), top), dialect="grbl").text) == []
    )
    rep, _ = verify_gcode(job.text, hm, resolution=0.1, uncut_tol=0.3 + 1.5 + 0.05)
    dev = rep.deviation[rep.part]
    assert rep.crashes == 0
    assert dev.min() >= 0.3 - 0.02  # never into the stock to leave
    levels = np.unique(np.round(parse_gcode(job.text).xyz[:, 2], 3))
    assert levels.size > 5  # it went down level by level
    assert rep.uncut_area == 0.0  # and left no more than leave + one step anywhere


@pytest.mark.parametrize(
    "kw, what",
    [
        (dict(cutter="ball40"), "larger than the part"),
        (dict(feed=0.0), "feed"),
        (dict(feed=-100.0), "feed"),
        (dict(plunge=0.0), "plunge feed"),
        (dict(scallop=None, stepover=0.0), "stepover"),
        (dict(scallop=None, stepover=-1.0), "stepover"),
        (dict(scallop=0.0), "scallop"),
        (dict(leave=-0.1), "stock to leave"),
        (dict(resolution=0.0), "resolution"),
    ],
)
def test_bad_settings_are_refused_with_a_clear_error(kw, what):
    with pytest.raises(SettingError) as e:
        finish(**kw)
    assert what in str(e.value)


@pytest.mark.parametrize(
    "kw, what", [(dict(clearance=-5.0), "clearance"), (dict(z_offset=float("nan")), "z offset")]
)
def test_program_frame_is_refused_before_planning(kw, what, monkeypatch):
    # a finishing plan takes seconds to minutes; a bad clearance was refused only after it
    import appliance.cam.jobs as jobs

    def no_planning(*a, **k):
        raise AssertionError("planned before refusing the settings")

    monkeypatch.setattr(jobs, "finishing", no_planning)
    monkeypatch.setattr(jobs, "roughing", no_planning)
    with pytest.raises(SettingError, match=what):
        finish(**kw)
    with pytest.raises(SettingError, match=what):
        roughing_gcode(bowl(), RoughSettings(parse_cutter("flat6"), 12.0), **kw)


def test_heightmap_with_a_hole_is_refused():
    hm = bowl()
    hm.z[10:12, 10:13] = np.nan
    with pytest.raises(InkSliceError, match=r"6 cells with no height inside the part"):
        finish(hm)


def test_bad_cutter_names():
    for bad, what in (
        ("ball", "not a cutter name"),
        ("bull6", "needs a corner radius"),
        ("bull6r3", "corner radius"),
        ("flat6r1", "no corner radius"),
    ):
        with pytest.raises(SettingError, match=what):
            parse_cutter(bad)


def test_commands_end_to_end(tmp_path, capsys):
    from appliance.cli import main
    from appliance.outputs import write_heightmap_csv

    csv = tmp_path / "heightmap.csv"
    write_heightmap_csv(csv, bowl())
    out = tmp_path / "toolpath.gcode"
    rough = tmp_path / "rough.gcode"
    assert (
        main(
            [
                "toolpath",
                str(csv),
                "-o",
                str(out),
                "--scallop",
                "0.05",
                "--rough-out",
                str(rough),
                "--dialect",
                "grbl",
            ]
        )
        == 0
    )
    said = capsys.readouterr().out
    assert "estimated run time" in said and "passes" in said
    assert check_grbl(out.read_text()) == [] and check_grbl(rough.read_text()) == []
    assert main(["verify", str(out), "--against", str(csv), "--scallop", "0.05", "--max-gouge", "0.005"]) == 0
    said = capsys.readouterr().out
    assert "gouge" in said and "scallop: max" in said
    assert (tmp_path / "toolpath.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # errors: one line, exit 2, naming the file or setting
    assert main(["toolpath", str(tmp_path / "nope.csv"), "-o", str(out)]) == 2
    assert "nope.csv" in capsys.readouterr().err
    assert main(["toolpath", str(csv), "-o", str(out), "--feed", "0"]) == 2
    assert "feed" in capsys.readouterr().err
    assert main(["verify", str(out), "--against", str(csv), "--z-zero", "high"]) == 2


@pytest.fixture(scope="module")
def bowl_files(tmp_path_factory):
    from appliance.outputs import write_heightmap_csv

    d = tmp_path_factory.mktemp("bad")
    write_heightmap_csv(d / "bowl.csv", bowl())
    holes = bowl()
    holes.z[5:7, 5:8] = np.nan
    write_heightmap_csv(d / "holes.csv", holes)
    (d / "ok.gcode").write_text(finish().text)
    (d / "flat2d.gcode").write_text("G21 G90\nG1 X1 Y1 F100\nG1 X5 Y5\nM2\n")
    return d


@pytest.mark.parametrize(
    "argv, where, what",
    [
        (["toolpath", "{d}/bowl.csv", "--cutter", "ball40"], "cutter", "larger than the part"),
        (["toolpath", "{d}/bowl.csv", "--feed", "0"], "feed", "must be > 0"),
        (["toolpath", "{d}/bowl.csv", "--feed", "-100"], "feed", "must be > 0"),
        (["toolpath", "{d}/bowl.csv", "--stepover", "0"], "stepover", "must be > 0"),
        (["toolpath", "{d}/bowl.csv", "--stepover", "-0.5"], "stepover", "must be > 0"),
        (["toolpath", "{d}/bowl.csv", "--scallop", "-0.01"], "scallop", "must be > 0"),
        (["toolpath", "{d}/bowl.csv", "--angle", "nan"], "angle", "degrees"),
        (
            ["verify", "{d}/ok.gcode", "--against", "{d}/holes.csv"],
            "{d}/holes.csv",
            "no height inside the part",
        ),
        (
            ["verify", "{d}/ok.gcode", "--against", "{d}/bowl.csv", "--resolution", "0"],
            "resolution",
            "must be > 0",
        ),
        (
            ["verify", "{d}/ok.gcode", "--against", "{d}/bowl.csv", "--edge-band", "-1"],
            "edge band",
            "must be >= 0",
        ),
        (
            ["verify", "{d}/ok.gcode", "--against", "{d}/bowl.csv", "--scallop", "0"],
            "--scallop",
            "must be > 0",
        ),
        # were: a program with `G0 Znan` and exit 0; a "program never sets Z" traceback (twice);
        # a --max-gouge check that always passed
        (["toolpath", "{d}/bowl.csv", "--z-offset", "nan"], "z offset", "must be a number"),
        (
            ["verify", "{d}/ok.gcode", "--against", "{d}/bowl.csv", "--z-zero", "nan"],
            "--z-zero",
            "must be a number",
        ),
        (
            ["verify", "{d}/flat2d.gcode", "--against", "{d}/bowl.csv", "--cutter", "ball6"],
            "{d}/flat2d.gcode",
            "never sets Z",
        ),
        (
            ["verify", "{d}/ok.gcode", "--against", "{d}/bowl.csv", "--max-gouge", "nan"],
            "--max-gouge",
            "must be >= 0",
        ),
    ],
)
def test_bad_input_is_one_line_naming_where_and_what(bowl_files, tmp_path, capsys, argv, where, what):
    from appliance.cli import main

    argv = [a.format(d=bowl_files) for a in argv]
    if argv[0] == "toolpath":
        argv += ["-o", str(tmp_path / "out.gcode")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith(f"inkslice: error: {where.format(d=bowl_files)}: ") and what in err, err
    assert not (tmp_path / "out.gcode").exists()


def test_every_dialect_of_a_dissertation_sample_passes_its_checkers(tmp_path):
    # sample 4 (the steep 10 mm saddle), one plan written in every dialect
    from appliance.cam.jobs import finishing_gcodes
    from appliance.cam.posts import DIALECT_NAMES

    s = surfaces.get("sample4")
    x0, x1, y0, y1 = s.bounds
    hm = grid_map(s.height, x0, x1, y0, y1, 0.2)
    st = FinishSettings(parse_cutter("ball1"), scallop=None, stepover=0.25, resolution=0.05)
    jobs = finishing_gcodes(hm, st, DIALECT_NAMES)
    assert set(jobs) == set(DIALECT_NAMES)
    for d, job in jobs.items():
        r = _rs274(tmp_path, job.text)
        assert r.returncode == 0, (d, r.stdout + r.stderr)
    assert check_grbl(jobs["grbl"].text) == []
    assert check_fanuc(jobs["fanuc"].text) == []
    # one plan: every dialect but the dissertation's describes the same moves
    ref = parse_gcode(jobs["linuxcnc"].text).xyz
    for d in ("grbl", "mach3", "fanuc"):
        assert np.nanmax(np.abs(parse_gcode(jobs[d].text).xyz - ref)) < 0.0011


def test_words_written_in_one_pass_read_as_each_written_alone():
    # motion_lines formats every coordinate of a program at once: the same digits as
    # gcode_number, a negative that rounds to zero included ("-0.000" is written "0.000")
    from appliance.cam.posts import _numbers, gcode_number

    v = np.array([0.0, -0.0, -0.0004, -0.0005, -0.00049, 0.0005, -0.01, -10.0, 12.34565, -1e-12, 3e5])
    for dec in (0, 1, 3, 4):
        assert _numbers(v, dec) == [gcode_number(x, dec) for x in v]
    assert _numbers(np.array([-0.0004]), 3) == ["0.000"]


def test_a_program_asked_for_without_a_scallop_gets_the_same_one_everywhere():
    """`inkslice toolpath`, `inkslice process` and the daemon's setting finish to one default
    scallop: the toolpath command's own 0.01 mm took 13 min and 590 MB on the blade's map."""
    from appliance.cli import build_parser
    from appliance.daemon.settings_schema import SCHEMA

    parser = build_parser()
    toolpath = parser.parse_args(["toolpath", "heightmap.csv"])
    process = parser.parse_args(["process", "scan", "-o", "out"])
    verify = parser.parse_args(["verify", "toolpath.gcode", "--against", "heightmap.csv"])
    daemon = next(s.default for s in SCHEMA if s.key == "scallop_mm")
    assert toolpath.scallop == process.scallop == verify.scallop == daemon == 0.05
