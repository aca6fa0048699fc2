"""The output contract of `inkslice process` and the daemon.

A run either leaves the complete set (height map, STL, finishing program,
report, pictures) or fails with one line naming the reason and leaves the
output folder as it was. The folder is replaced whole: nothing of an earlier
run survives beside the new set. The part stands on the base: heights below
it are clamped and gaps inside the part filled, counted, never fatal.
"""

import json
import os

import numpy as np
import pytest

from appliance import atomicio
from appliance.cli import main
from appliance.outputs import read_heightmap_csv, write_heightmap_csv
from appliance.surface.base import stand_on_base
from appliance.surface.heightmap import HeightMap

SET = {
    "heightmap.csv",
    "surface.stl",
    "toolpath.gcode",
    "toolpath-dissertation.gcode",
    "report.md",
    "report.json",
    "error_inkslice_fit.png",
}


def dome(n=41, dip=0.0):
    """A 40 mm dome on a block 4 mm high; `dip`: its rim pulled that far below the base top."""
    x = np.linspace(0, 40, n)
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X - 20, Y - 20)
    z = 4 + 10 * np.clip(1 - (r / 20) ** 2, 0, None)
    rim = (X < 1.5) | (X > 38.5)
    z[rim] = -dip if dip else z[rim]
    return HeightMap(x, x, z)


# -- the base plane ----------------------------------------------------------------


def test_heights_below_the_base_are_clamped_to_it_and_counted():
    hm, fix = stand_on_base(dome(dip=0.7))
    assert np.nanmin(hm.z) == 0.0
    assert fix.clamped_cells == 2 * 2 * 41 and fix.deepest_dip_mm == pytest.approx(0.7)
    assert "deepest 0.700 mm" in fix.sentences()[0]
    untouched, none = stand_on_base(dome())
    assert not none.changed and untouched.z.min() == pytest.approx(4.0)


def test_a_gap_inside_the_part_is_filled_from_its_neighbours_a_wide_hole_is_the_base():
    hm = dome()
    truth = hm.z.copy()
    hm.z[20, 4:8] = np.nan  # a narrow gap the waterlines missed
    X, Y = hm.grid()
    hole = np.hypot(X - 20, Y - 20) < 7  # a hole down to the base, 14 mm across
    hm.z[hole] = np.nan
    fixed, fix = stand_on_base(hm)
    assert fix.filled_cells == 4 and fix.base_cells == int(hole.sum())
    assert np.all(fixed.z[hole] == 0.0)
    assert np.abs(fixed.z[20, 4:8] - truth[20, 4:8]).max() < 0.3
    assert np.isfinite(fixed.z).all()


def test_toolpath_accepts_a_map_below_the_base_by_the_same_clamp(tmp_path, capsys):
    csv = tmp_path / "dips.csv"
    hm = dome(dip=0.4)
    hm.z[20, 30] = np.nan  # and one cell with no height inside the part
    write_heightmap_csv(csv, hm)
    out = tmp_path / "toolpath.gcode"
    assert main(["toolpath", str(csv), "-o", str(out), "--scallop", "0.2"]) == 0
    said = capsys.readouterr().out
    assert "164 cells were below the base top (deepest 0.400 mm)" in said
    assert "1 cells with no height inside the part were filled" in said
    zs = [
        float(w[1:])
        for line in out.read_text().splitlines()
        if line.startswith("G1")
        for w in line.split()
        if w.startswith("Z")
    ]
    assert zs and min(zs) >= -1e-6  # the tip never goes below the base top


# -- the folder is replaced whole --------------------------------------------------


def test_replace_folder_leaves_exactly_the_new_set_and_keeps_what_it_is_told(tmp_path):
    out = tmp_path / "job"
    (out / "scan" / "frames").mkdir(parents=True)
    (out / "scan" / "frames" / "0001.png").write_bytes(b"frame")
    (out / "toolpath.gcode").write_text("old program")
    (out / "error_seed_lsq3.png").write_bytes(b"old picture")
    atomicio.replace_folder(out, {"heightmap.csv": b"x,y,z\n", "toolpath.gcode": b"new"}, keep=["scan"])
    assert sorted(p.name for p in out.iterdir()) == ["heightmap.csv", "scan", "toolpath.gcode"]
    assert (out / "toolpath.gcode").read_bytes() == b"new"
    assert (out / "scan" / "frames" / "0001.png").read_bytes() == b"frame"
    assert [p.name for p in tmp_path.iterdir()] == ["job"]  # no staging folder left


def test_a_crash_while_building_the_set_leaves_the_old_one(tmp_path, monkeypatch):
    out = tmp_path / "out"
    atomicio.replace_folder(out, {"a.txt": b"old a", "b.txt": b"old b"})
    written = []

    def crash_on_second(path, data):
        if written:
            raise OSError(28, "No space left on device")
        written.append(path)
        path.write_bytes(data)

    monkeypatch.setattr(atomicio, "_write_new", crash_on_second)
    with pytest.raises(OSError):
        atomicio.replace_folder(out, {"a.txt": b"new a", "b.txt": b"new b"})
    assert {p.name: p.read_bytes() for p in out.iterdir()} == {"a.txt": b"old a", "b.txt": b"old b"}
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_a_crash_between_the_two_renames_of_the_fallback_swap_is_undone_next_time(tmp_path):
    out = tmp_path / "out"
    atomicio.replace_folder(out, {"a.txt": b"old"})
    parked = tmp_path / f"{atomicio.STAGING_PREFIX}out.old.123"
    os.rename(out, parked)  # the power went after the first rename
    (tmp_path / f"{atomicio.STAGING_PREFIX}out.new.xyz").mkdir()
    atomicio.clear_staging(out)
    assert (out / "a.txt").read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def _file_as_out(tmp_path):
    (tmp_path / "OUT").write_text("not a folder")
    return tmp_path / "OUT"


def _file_as_parent(tmp_path):
    (tmp_path / "afile").write_text("not a folder")
    return tmp_path / "afile" / "OUT"


@pytest.mark.parametrize(
    "where, what",
    [
        (_file_as_out, "exists and is not a folder; give a folder for the outputs"),
        (_file_as_parent, "cannot be created: {tmp}/afile is not a folder"),
    ],
)
def test_an_output_that_cannot_be_a_folder_is_one_line_before_any_work(tmp_path, capsys, where, what):
    out = where(tmp_path)
    assert main(["process", str(tmp_path / "no-scan-here"), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"inkslice: error: {out}: " + what.format(tmp=tmp_path)]
    assert (tmp_path / ("OUT" if (tmp_path / "OUT").exists() else "afile")).read_text() == "not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_an_unwritable_output_parent_is_one_line_before_any_work(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        assert main(["process", str(tmp_path / "no-scan-here"), "-o", str(locked / "OUT")]) == 2
        assert "cannot be written" in capsys.readouterr().err
    finally:
        locked.chmod(0o700)


# -- `inkslice process` ------------------------------------------------------------


@pytest.fixture
def cone_scan(tmp_path):
    from scan_helpers import write_cone_scan

    write_cone_scan(tmp_path / "cone")
    return tmp_path / "cone"


def _files(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_no_file_of_an_earlier_run_is_left_beside_the_new_set(cone_scan, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "surface.stl").write_bytes(b"solid an earlier part")  # the seed pipeline writes none
    (out / "toolpath.gcode").write_text("G1 Z-5 (an earlier part's program)\n")
    (out / "error_lsq3.png").write_bytes(b"an earlier --compare")
    assert main(["process", str(cone_scan), "-o", str(out), "--pipeline", "seed"]) == 0
    assert set(_files(out)) == {"heightmap.csv", "toolpath.gcode", "report.md", "report.json"}
    assert "an earlier" not in (out / "toolpath.gcode").read_text()


def test_a_run_that_cannot_make_a_program_exits_2_and_leaves_the_old_set(cone_scan, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["process", str(cone_scan), "-o", str(out), "--pipeline", "seed"]) == 0
    before = _files(out)
    capsys.readouterr()
    # a 60 mm ball on a 30 mm cone: no finishing program exists
    assert main(["process", str(cone_scan), "-o", str(out), "--cutter", "ball60"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkslice: error: finishing program: cannot be made: ")
    assert "larger than the part" in err[0]
    assert _files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cone", "out"]


# -- the daemon --------------------------------------------------------------------


def test_the_daemon_fails_a_job_whose_processing_wrote_no_program_and_keeps_its_scan(tmp_path):
    from daemon_helpers import SCAN, service, wait_final

    from appliance.atomicio import write_text

    def no_program(scan_folder, out_folder, options, stop=None):
        """What processing did before the contract: a height map, a note, no G-code."""
        write_text(out_folder / "heightmap.csv", "x,y,z\n0,0,1\n")
        return {"outputs": ["heightmap.csv"], "notes": ["no finishing program: ..."]}

    svc, _ = service(tmp_path, processor=no_program)
    try:
        job = wait_final(svc, svc.start_scan(SCAN))
        assert job["status"] == "failed"
        assert job["reason"].startswith("processing: no finishing program (toolpath.gcode) was written")
        folder = svc.store.job_dir(job["id"])
        assert len(json.loads((folder / "scan" / "scan.json").read_text())["frames"]) == job["levels_done"]
    finally:
        svc.close()


def test_a_daemon_job_folder_is_replaced_whole_but_its_scan_is_kept(tmp_path):
    from scan_helpers import write_cone_scan

    from appliance.daemon.processing import JOB_OWN, checked_outputs, in_process, options_for
    from appliance.daemon.settings import DEFAULTS

    job = tmp_path / "job"
    write_cone_scan(job / "scan")
    (job / "surface.stl").write_bytes(b"an earlier run's mesh")
    options = options_for({**DEFAULTS, "pipeline": "seed"})
    assert options["keep"] == list(JOB_OWN)
    result = in_process(job / "scan", job, options)
    assert {"heightmap.csv", "report.md", "toolpath.gcode"} <= set(checked_outputs(result, job))
    assert "surface.stl" not in result["outputs"]
    assert sorted(p.name for p in job.iterdir()) == sorted(result["outputs"] + list(JOB_OWN))
    assert (job / "scan" / "frames" / "0001.png").is_file()
    with pytest.raises(Exception, match="no finishing program"):
        checked_outputs({"outputs": ["heightmap.csv"]}, job)


# -- a scan that runs down to the base ----------------------------------------------


def test_a_scan_whose_last_frame_is_at_level_0_gets_its_program_and_the_clamp_is_counted(tmp_path):
    """A real scan runs until the base top reaches the ink, and the base is lit like the part:
    its outline in that last frame is not the part's waterline, the part is not that wide,
    and the set (with its finishing program) is written, the base plane counted."""
    import dataclasses

    from appliance.sim import surfaces
    from appliance.sim.render import Effects
    from appliance.sim.rig import Rig
    from appliance.sim.scanrender import render_scan, scan_levels

    sphere = surfaces.get("sphere")  # a cap on a disc of radius 29 mm at (50, 50)
    levels = scan_levels(sphere, 2.0) + [0.0]
    rig = Rig(width=1024, height=768, focal_px=1900.0, principal_u=515.0, principal_v=381.5)
    render_scan(
        sphere,
        tmp_path / "sphere",
        levels=levels,
        rig=rig,
        effects=dataclasses.replace(Effects(), base_shows=True),
    )
    out = tmp_path / "out"
    assert (
        main(["process", str(tmp_path / "sphere"), "-o", str(out), "--grid", "40", "--scallop", "0.2"]) == 0
    )
    assert SET <= set(_files(out))
    report = json.loads((out / "report.json").read_text())
    fit = report["diagnostics"]["fit"]
    assert any("level 0 mm not used" in n for n in fit["notes"])
    hm = read_heightmap_csv(out / "heightmap.csv")
    assert hm.x[0] > 19 and hm.x[-1] < 81 and hm.y[0] > 19 and hm.y[-1] < 81  # the part, not the base
    assert np.nanmin(hm.z) >= 0.0
    assert set(fit["base"]) == {"clamped_cells", "deepest_dip_mm", "filled_cells", "base_cells"}
    assert "Base plane" in (out / "report.md").read_text()
    assert report["statistics"]["inkslice:fit"]["Ea"] < 0.1


def test_a_folder_holding_other_files_is_refused_not_emptied(cone_scan, tmp_path, capsys):
    """OUT is replaced whole, so `-o .` or `-o SCAN` must not wipe what is there."""
    for out in (cone_scan, tmp_path):
        before = sorted(p.name for p in out.iterdir())
        assert main(["process", str(cone_scan), "-o", str(out), "--pipeline", "seed"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "which no run wrote; the output folder is replaced whole" in err[0]
        assert sorted(p.name for p in out.iterdir()) == before
