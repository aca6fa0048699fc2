"""Long commands show their progress: a bar redrawn in place on a terminal, plain lines in a pipe."""

import io

from appliance import progress
from appliance.cli import main


def test_on_a_terminal_a_counted_stage_is_a_bar_redrawn_in_place_and_prints_go_above_it():
    out = io.StringIO()
    with progress.shown(out, tty=True):
        progress.stage("waterlines", total=4)
        for i in range(1, 5):
            progress.step(i)
        progress.stage("surface (fit)")
    text = out.getvalue()
    assert "\r\x1b[Kwaterlines [------------------------]   0 % 0/4" in text
    assert "waterlines [############------------]  50 % 2/4" in text
    assert "waterlines [########################] 100 % 4/4" in text and " done\n" in text
    assert "surface (fit) ... " in text
    assert text.count("\n") == 2  # one finished line per stage, nothing else


def test_in_a_pipe_a_stage_is_plain_lines_its_start_its_quarters_and_its_time():
    out = io.StringIO()
    with progress.shown(out, tty=False):
        progress.stage("frames", total=8)
        for i in range(1, 9):
            progress.step(i)
    lines = out.getvalue().splitlines()
    assert lines[0] == "frames ... (8)"
    assert [l.split(" (")[0] for l in lines[1:4]] == ["frames: 25 %", "frames: 50 %", "frames: 75 %"]
    assert lines[4].startswith("frames: done in ") and len(lines) == 5
    assert "\r" not in out.getvalue()


def test_nobody_listening_costs_nothing_and_prints_nothing(capsys):
    progress.stage("waterlines", total=3)  # as in the daemon's processing child
    progress.step(2)
    assert capsys.readouterr() == ("", "")


def test_toolpath_and_verify_say_their_stages_in_a_pipe(tmp_path, capsys):
    import numpy as np

    from appliance.outputs import write_heightmap_csv
    from appliance.surface.heightmap import HeightMap

    x = np.linspace(0, 20, 41)
    X, Y = np.meshgrid(x, x)
    z = np.clip(6 - ((X - 10) ** 2 + (Y - 10) ** 2) / 15, 0, None)
    csv = tmp_path / "dome.csv"
    write_heightmap_csv(csv, HeightMap(x, x, z))
    out = tmp_path / "dome.gcode"
    assert main(["toolpath", str(csv), "-o", str(out), "--scallop", "0.2"]) == 0
    said = capsys.readouterr().out
    assert "finishing program ...\n" in said and "finishing program: done in " in said
    assert "estimated run time" in said  # the command's own lines still there
    assert main(["verify", str(out), "--against", str(csv), "--scallop", "0.2", "--max-gouge", "1"]) == 0
    said = capsys.readouterr().out
    assert "simulated milling ...\n" in said and "simulated milling: done in " in said


def test_render_and_process_say_frames_waterlines_surface_and_toolpath(tmp_path, capsys):
    scan = tmp_path / "scan"
    assert main(["render", "sample4", "-o", str(scan), "--step", "10", "--effects", "clean"]) == 0
    said = capsys.readouterr().out
    assert "frames ... (4)" in said and "frames: done in " in said and "4 frames of sample4" in said
    assert main(["process", str(scan), "-o", str(tmp_path / "out"), "--grid", "20", "--scallop", "0.3"]) == 0
    said = capsys.readouterr().out
    stages = [l.split(" ...")[0] for l in said.splitlines() if " ..." in l]
    assert stages[:2] == ["waterlines", "surface (fit)"] and stages[-2:] == ["toolpath", "writing outputs"]
    assert f"{tmp_path / 'out'}/heightmap.csv" in said


def test_timed_clocks_each_stage_and_the_peak_memory_when_it_ended():
    with progress.timed() as clock:
        progress.stage("waterlines", total=2)
        progress.step(1)
        progress.stage("toolpath")
        block = bytearray(20_000_000)  # the peak rises during the toolpath
        progress.stage("writing outputs")
        del block
    assert list(clock.seconds) == ["waterlines", "toolpath", "writing outputs"]
    assert all(s >= 0 for s in clock.seconds.values())
    assert clock.peak_mb["toolpath"] >= clock.peak_mb["waterlines"]
    progress.stage("after the block")  # nobody listens again: nothing recorded
    assert "after the block" not in clock.seconds
