"""`inkslice process` end to end on a hand-made scan, and on bad input.

Every bad input must give one error line naming the file and the problem,
a non-zero exit code, and leave what was already in OUT untouched.
"""

import json

import numpy as np
import pytest
from scan_helpers import write_cone_scan

from appliance.cli import main
from appliance.outputs import read_heightmap_csv


@pytest.fixture
def scan(tmp_path):
    folder = tmp_path / "cone"
    write_cone_scan(folder)
    return folder


def run_cli(*args):
    return main([str(a) for a in args])


def test_dissertation_pipeline_writes_its_outputs(scan, tmp_path, capsys):
    out = tmp_path / "out"
    assert run_cli("process", scan, "-o", out, "--pipeline", "seed", "--method", "nearest") == 0
    names = {p.name for p in out.iterdir()}
    assert {"heightmap.csv", "toolpath.gcode", "report.md", "report.json"} <= names
    hm = read_heightmap_csv(out / "heightmap.csv")
    assert hm.z.shape == (50, 50)
    # the cone's apex region is the highest, its rim the lowest
    assert np.nanmax(hm.z) == pytest.approx(19, abs=0.01)
    assert np.nanmin(hm.z) == pytest.approx(5, abs=0.01)
    gcode = (out / "toolpath.gcode").read_text().splitlines()
    assert gcode[0] == "N00001 G90 G21" and gcode[1] == "N00002 M03 S1500" and gcode[-1].endswith("M30")
    assert "F1500" in gcode[2]


def test_our_pipeline_writes_mesh_and_compensated_gcode(scan, tmp_path):
    out = tmp_path / "out"
    assert run_cli("process", scan, "-o", out, "--scallop", "0.1") == 0  # a coarse finish: fast
    names = {p.name for p in out.iterdir()}
    assert {
        "heightmap.csv",
        "surface.stl",
        "toolpath.gcode",
        "toolpath-dissertation.gcode",
        "report.md",
        "report.json",
    } <= names
    hm = read_heightmap_csv(out / "heightmap.csv")
    X, Y = hm.grid()
    r = np.hypot(X - 30, Y - 30)
    inner = np.isfinite(hm.z) & (r < 14) & (r > 2)
    # the hand-made cone is z = 20 - r: inside the scanned levels the fit follows it closely
    assert np.max(np.abs(hm.z[inner] - (20 - r[inner]))) < 0.1
    stl = (out / "surface.stl").read_bytes()
    assert len(stl) == 84 + 50 * int.from_bytes(stl[80:84], "little")
    gcode = (out / "toolpath.gcode").read_text()
    assert "G1" in gcode and "M30" in gcode
    # every cell says how sure it is; the report, its picture and the program's header agree
    assert hm.sigma is not None and np.all(np.isfinite(hm.sigma[np.isfinite(hm.z)]))
    assert (out / "uncertainty.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    unc = json.loads((out / "report.json").read_text())["diagnostics"]["uncertainty"]
    report = (out / "report.md").read_text()
    assert "Uncertainty per cell" in report
    if unc["regions"]:  # the cone's apex sits above the top frame
        first = unc["regions"][0]
        assert f"| 1 | {first['xmin']:.1f} .. {first['xmax']:.1f} |" in report
        assert f"low confidence 1: X {first['xmin']:.1f}..{first['xmax']:.1f}" in gcode
    else:
        assert "confidence: every cell of the height map within 0.1 mm" in gcode


def test_process_with_truth_reports_statistics(scan, tmp_path):
    (tmp_path / "cone.truth.json").write_text(json.dumps({"surface": "cone"}))
    out = tmp_path / "out"
    # the test cone is not the library's reference cone, so just check the wiring:
    assert run_cli("process", scan, "-o", out, "--compare", "--scallop", "0.1") == 0
    report = json.loads((out / "report.json").read_text())
    assert report["truth"] == "cone"
    assert set(report["statistics"]) == {"inkslice:fit"} | {
        f"seed:{m}" for m in ("captured", "spline", "nearest", "lsq1", "lsq2", "lsq3")
    }
    assert (out / "error_lsq3.png").stat().st_size > 1000
    assert (out / "error_inkslice_fit.png").stat().st_size > 1000


def _prefill(out):
    out.mkdir()
    (out / "heightmap.csv").write_text("x,y,z\n1,2,3\n")
    return {p.name: p.read_bytes() for p in out.iterdir()}


def _assert_untouched(out, before):
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.parametrize(
    "breakage, expected",
    [
        ("missing_json", "scan.json: missing"),
        ("malformed_json", "scan.json: not valid JSON"),
        ("level_not_number", "frames[2].level_mm is not a number"),
        ("frame_corrupt", "0003.png: frame does not load"),
        ("frame_missing", "0003.png: frame file is missing"),
        ("frame_wrong_size", "0003.png: frame is 10x10"),
        ("no_camera", "scan.json: 'camera' is missing"),
        ("singular_homography", "camera.homography is singular"),
    ],
)
def test_bad_input_gives_one_clear_line_and_keeps_out(scan, tmp_path, capsys, breakage, expected):
    doc = json.loads((scan / "scan.json").read_text())
    if breakage == "missing_json":
        (scan / "scan.json").unlink()
    elif breakage == "malformed_json":
        (scan / "scan.json").write_text('{"format": "inkslice.scan/1", "frames": [')
    elif breakage == "level_not_number":
        doc["frames"][2]["level_mm"] = "twelve"
    elif breakage == "frame_corrupt":
        data = (scan / "frames/0003.png").read_bytes()
        (scan / "frames/0003.png").write_bytes(data[: len(data) // 3])
    elif breakage == "frame_missing":
        (scan / "frames/0003.png").unlink()
    elif breakage == "frame_wrong_size":
        import cv2

        cv2.imwrite(str(scan / "frames/0003.png"), np.zeros((10, 10, 3), np.uint8))
    elif breakage == "no_camera":
        del doc["camera"]
    elif breakage == "singular_homography":
        doc["camera"]["homography"] = [[0, 0, 0], [0, 0, 0], [0, 0, 1]]
    if breakage in ("level_not_number", "no_camera", "singular_homography"):
        (scan / "scan.json").write_text(json.dumps(doc))
    out = tmp_path / "out"
    before = _prefill(out)
    capsys.readouterr()
    assert run_cli("process", scan, "-o", out) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("inkslice: error: ")
    assert expected in err[0]
    _assert_untouched(out, before)


def test_missing_scan_folder(tmp_path, capsys):
    assert run_cli("process", tmp_path / "nope", "-o", tmp_path / "out") == 2
    assert "scan folder does not exist" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_unknown_keys_are_kept(scan):
    from appliance.scanfile import load_scan, write_scan_json

    s = load_scan(scan)
    assert s.extra["note"] == "unknown keys are kept"
    write_scan_json(s)
    assert json.loads((scan / "scan.json").read_text())["note"] == "unknown keys are kept"


@pytest.mark.parametrize("falls", [True, False, None])
def test_a_scan_saying_its_ink_falls_under_the_camera_is_processed_so(tmp_path, monkeypatch, falls):
    """scan.json's tank.surface_falls reaches the surface fit (absent: the ink is held)."""
    from appliance.scanfile import load_scan, write_scan_json
    from appliance.surface import reconstruct as rc

    scan = write_cone_scan(tmp_path / "scan")
    tank = {"inner_area_mm2": 22500.0}
    if falls is not None:
        tank["surface_falls"] = falls
    scan.extra["tank"] = tank
    write_scan_json(scan)
    asked = []
    real = rc.reconstruct
    monkeypatch.setattr(rc, "reconstruct", lambda w, g, o=None: asked.append(o) or real(w, g, o))
    assert main(["process", str(tmp_path / "scan"), "-o", str(tmp_path / "out")]) == 0
    assert load_scan(tmp_path / "scan").extra["tank"] == tank
    assert asked and all(o.ink_falls is bool(falls) for o in asked)
