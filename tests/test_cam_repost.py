"""Posting a job again from its height map (another cutter, scallop or dialect, no
rescan), the file names, and the preview JSON beside every program."""

import json

import numpy as np
from cam_helpers import grid_map

from appliance.cam.dialects import check_grbl
from appliance.cam.gcodeparse import parse_gcode
from appliance.cam.preview import FORMAT, decode
from appliance.cli import main
from appliance.outputs import write_heightmap_csv


def job_folder(tmp_path, name="bowl-job"):
    job = tmp_path / name
    job.mkdir()
    hm = grid_map(lambda X, Y: 6 + 0.02 * ((X - 10) ** 2 + (Y - 8) ** 2), 0, 20, 0, 16, 1.0)
    write_heightmap_csv(job / "heightmap.csv", hm)
    return job


def test_a_job_is_posted_again_for_another_dialect_and_cutter(tmp_path, capsys):
    job = job_folder(tmp_path)
    assert main(["toolpath", str(job), "--dialect", "grbl", "--scallop", "0.05"]) == 0
    assert (
        main(["toolpath", str(job), "--dialect", "linuxcnc", "--cutter", "ball4", "--scallop", "0.05"]) == 0
    )
    grbl = job / "bowl-job-finish-ball6-grbl.nc"
    lcnc = job / "bowl-job-finish-ball4-linuxcnc.nc"
    assert grbl.is_file() and lcnc.is_file()
    assert check_grbl(grbl.read_text()) == []
    assert "inkslice cutter: ball D4.000" in lcnc.read_text()

    # the same surface both times: both programs end up at the same lowest point of the dish
    # (inside the outline: beyond it each cutter rolls down over the rim by its own radius)
    def lowest_inside(path):
        xyz = parse_gcode(path.read_text()).xyz
        inside = (xyz[:, 0] >= 3) & (xyz[:, 0] <= 17) & (xyz[:, 1] >= 3) & (xyz[:, 1] <= 13)
        return np.nanmin(xyz[inside, 2])

    lows = [lowest_inside(p) for p in (grbl, lcnc)]
    assert abs(lows[0] - lows[1]) < 0.01
    out = capsys.readouterr().out
    assert str(grbl) in out and str(lcnc) in out


def test_the_preview_tells_rapids_from_feeds_and_marks_tool_changes(tmp_path):
    job = job_folder(tmp_path)
    assert (
        main(
            [
                "toolpath",
                str(job),
                "--operations",
                "rough T1, finish T2",
                "--dialect",
                "mach3",
                "--scallop",
                "0.1",
            ]
        )
        == 0
    )
    program = job / "bowl-job-rough-flat6-finish-ball6-mach3.nc"
    doc = json.loads(program.with_suffix(".preview.json").read_text())
    assert doc["format"] == FORMAT
    assert [c["tool"] for c in doc["changes"]] == [1, 2]
    assert {p["kind"] for p in doc["paths"]} == {"rapid", "feed"}
    parsed = parse_gcode(program.read_text())
    # every feed move of the program is in the preview, to the hundredth of a mm
    feed_pts = np.vstack([decode(p)[1:] for p in doc["paths"] if p["kind"] == "feed"])
    assert len(feed_pts) == int((parsed.kind == 1).sum())
    assert np.abs(feed_pts - parsed.xyz[parsed.kind == 1]).max() <= 0.006
    # rapids stay at the safe height or go straight up
    lo, hi = np.array(doc["bounds"])
    for p in (p for p in doc["paths"] if p["kind"] == "rapid"):
        pts = decode(p)
        for a, b in zip(pts[:-1], pts[1:]):
            assert np.allclose(a[:2], b[:2]) or (a[2] == b[2] == hi[2])


def test_a_folder_without_a_height_map_is_one_clear_error(tmp_path, capsys):
    empty = tmp_path / "empty-job"
    empty.mkdir()
    assert main(["toolpath", str(empty), "--dialect", "grbl"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"inkslice: error: {empty}: holds no heightmap.csv: process the scan first"
    assert list(empty.iterdir()) == []
