"""Meniscus calibration from a reference part, end to end on the virtual bench:
render a sphere with a known meniscus, `inkslice calibrate --reference`, then
`inkslice process --meniscus` on a scan of another part with the same ink."""

import json

import numpy as np
import pytest

from appliance.cli import main
from appliance.outputs import read_heightmap_csv
from appliance.sim import surfaces
from appliance.sim.render import Effects
from appliance.sim.rig import Rig
from appliance.sim.scanrender import render_scan

RIG = Rig(width=1024, height=768, focal_px=1900.0, principal_u=515.0, principal_v=381.5)
INK = Effects(meniscus=True, capillary_length_mm=2.0, contact_angle_deg=10.0, blur_sigma_px=0.7)


@pytest.fixture(scope="module")
def meniscus_file(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("men")
    render_scan("sphere", tmp / "sphere", step_mm=1.5, rig=RIG, effects=INK, seed=3, workers=2)
    out = tmp / "meniscus.json"
    assert main(["calibrate", "--reference", "sphere", "--scan", str(tmp / "sphere"), "--out", str(out)]) == 0
    return out


def test_reference_scan_recovers_the_inks_meniscus(meniscus_file):
    doc = json.loads(meniscus_file.read_text())
    assert doc["capillary_length_mm"] == pytest.approx(2.0, abs=0.1)
    assert doc["contact_angle_deg"] == pytest.approx(10.0, abs=1.5)


@pytest.mark.slow
def test_the_correction_makes_another_part_measure_better(meniscus_file, tmp_path):
    """The plateau's shoulders (slopes 0 .. 1.4) are where the ink climbs by the wall
    slope: there the correction must take the rise out. Its flat top and block come out
    of the ink all at once, a level step (1.5 mm) wide, so the whole part's Ea is mostly
    first exposure's doubt: it must not get worse."""
    render_scan("plateau", tmp_path / "plateau", step_mm=1.5, rig=RIG, effects=INK, seed=4, workers=2)
    plateau = surfaces.get("plateau")
    errs, shoulder = {}, {}
    for name, extra in (("off", []), ("on", ["--meniscus", str(meniscus_file)])):
        out = tmp_path / name
        assert main(["process", str(tmp_path / "plateau"), "-o", str(out), "--scallop", "0.2", *extra]) == 0
        errs[name] = json.loads((out / "report.json").read_text())["statistics"]["inkslice:fit"]["Ea"]
        hm = read_heightmap_csv(out / "heightmap.csv")
        X, Y = np.meshgrid(hm.x, hm.y)
        r = np.hypot(X - 50, Y - 45)
        on_shoulder = (r > 24) & (r < 36)
        shoulder[name] = np.nanmean(np.abs(hm.z - plateau.height(X, Y))[on_shoulder])
    # measured: shoulders 1.16 -> 0.023 mm; the whole part 1.85 -> 1.50 mm
    assert shoulder["on"] < 0.1 * shoulder["off"], shoulder
    assert errs["on"] < errs["off"], errs


def test_a_ball_lying_anywhere_on_the_base_recovers_the_inks_meniscus(tmp_path):
    """The reference a user can buy: a 25.4 mm precision ball, put down by hand off the centre.
    It is found in the scan, then fitted like the sphere."""
    ball = surfaces.ball(25.4, 44.0, 56.0)
    levels = [round(26.0 - 0.75 * i, 3) for i in range(22)]  # 26 .. 10.25 mm: past its equator
    render_scan(ball, tmp_path / "ball", levels=levels, rig=RIG, effects=INK, seed=6, workers=2)
    out = tmp_path / "meniscus.json"
    assert (
        main(
            [
                "calibrate",
                "--reference",
                "ball",
                "--diameter",
                "25.4",
                "--scan",
                str(tmp_path / "ball"),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    doc = json.loads(out.read_text())
    assert doc["capillary_length_mm"] == pytest.approx(2.0, abs=0.15)
    assert doc["contact_angle_deg"] == pytest.approx(10.0, abs=2.0)


def test_reference_needs_a_scan(capsys):
    assert main(["calibrate", "--reference", "cone"]) == 2
    assert "--scan" in capsys.readouterr().err


def test_camera_calibration_needs_its_images(capsys):
    assert main(["calibrate", "--square-mm", "8"]) == 2
    assert "3 or more board images" in capsys.readouterr().err


def test_a_bad_meniscus_file_is_named(meniscus_file, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"capillary_length_mm": -3, "contact_angle_deg": 0}')
    render_scan("cone", tmp_path / "cone", levels=[20.0, 12.0], rig=RIG, effects=INK, seed=5)
    assert main(["process", str(tmp_path / "cone"), "-o", str(tmp_path / "out"), "--meniscus", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.json" in err and "impossible meniscus" in err
    assert not (tmp_path / "out").exists()
