"""Scan folders from the virtual bench, the virtual camera, and `inkslice render`."""

import json

import numpy as np
import pytest

from appliance.cli import main
from appliance.hw.base import Camera
from appliance.scanfile import load_scan, read_frame
from appliance.sim import physics
from appliance.sim import surfaces as S
from appliance.sim.camera import VirtualCamera
from appliance.sim.levels import ink_margins, sculpture_levels
from appliance.sim.render import Effects, render_frame
from appliance.sim.rig import Rig
from appliance.sim.scanrender import render_scan, scan_levels, truth_path


def test_levels_run_from_above_the_top_down_to_the_base():
    lv = scan_levels(S.get("sample1"), 1.0)
    assert lv[0] == 38.0 and lv[0] > S.get("sample1").z_max
    assert lv[-1] == 1.0 and all(a - b == 1.0 for a, b in zip(lv, lv[1:]))
    lv = scan_levels(S.get("cone"), 2.5)
    assert lv[0] == 25.0 and min(lv) >= 0.5 and min(lv) < 3.0


def test_a_bench_scan_from_above_starts_with_a_frame_that_shows_no_part():
    plateau = S.get("plateau")  # its flat top lies on a level (25 mm)
    dissertation = sculpture_levels(plateau, 1.0)
    daemon_like = sculpture_levels(plateau, 1.0, from_above=True)
    assert dissertation[0] < plateau.z_max == 25.0  # the top is above the first frame
    assert daemon_like[:2] == [26.0, 25.0] and daemon_like[2:] == dissertation
    # an ink that leaves a flat top while it stands up to 1.9 mm over it: the first frame
    # that shows no part is 27 mm
    assert sculpture_levels(plateau, 1.0, from_above=True, above_mm=1.9)[:3] == [27.0, 26.0, 25.0]


def test_the_inks_margins_widen_the_scan_by_its_rise_and_its_depression():
    """The second ink (l_c 2.3 mm, 35 deg) climbs a wall 2.12 mm and stands 1.38 mm over a flat
    top it has left, a pit's contact line up to sqrt(2) times that: the scan runs on 2.12 mm
    below the top's lowest point and starts 1.96 mm higher. No meniscus, no margins."""
    below, above = ink_margins(Effects(meniscus=True, capillary_length_mm=2.3, contact_angle_deg=35.0))
    assert below == pytest.approx(2 * 2.3 * np.sin(np.radians(55.0) / 2))
    assert above == pytest.approx(np.sqrt(2) * 2 * 2.3 * np.sin(np.radians(35.0) / 2))
    assert ink_margins(Effects(meniscus=True, capillary_length_mm=2.7, contact_angle_deg=0.0))[1] == 0.0
    assert ink_margins(Effects(meniscus=False)) == (0.0, 0.0)


def test_render_scan_writes_a_scan_and_its_truth_outside(tmp_path):
    folder = tmp_path / "scan"
    render_scan(
        "cone",
        folder,
        levels=[24.0, 15.0, 6.0],
        effects=Effects(displacement=True, lens_distortion=True),
        seed=7,
    )
    assert sorted(p.name for p in folder.iterdir()) == ["frames", "scan.json"]
    loaded = load_scan(folder)
    assert [f.level_mm for f in loaded.frames] == [24.0, 15.0, 6.0]
    assert loaded.extra["tank"]["inner_area_mm2"] == 22500.0
    rig = Rig()
    assert np.allclose(loaded.camera.homography, rig.homography())
    assert np.allclose(loaded.camera.dist, rig.dist_coeffs()) and loaded.camera.height_mm == 300.0
    img = read_frame(loaded, loaded.frames[1])
    assert img.shape == (1536, 2048, 3)
    truth = json.loads(truth_path(folder).read_text())
    assert truth["surface"] == "cone"
    want = [physics.true_level(S.get("cone"), L, 22500.0) for L in (24.0, 15.0, 6.0)]
    assert np.allclose(truth["levels_true_mm"], want)
    assert truth["levels_true_mm"][0] == 24.0 and truth["levels_true_mm"][2] < 6.0 - 0.5
    assert truth["effects"]["displacement"] is True and truth["meniscus"]["enabled"] is False
    # the frame is the one render_frame gives for that level and seed
    again = render_frame(
        "cone", 15.0, rig, Effects(displacement=True, lens_distortion=True), np.random.default_rng([7, 1])
    )
    assert np.array_equal(again, img)
    # the same scan from two processes is the same scan
    par = render_scan(
        "cone",
        tmp_path / "par",
        levels=[24.0, 15.0, 6.0],
        effects=Effects(displacement=True, lens_distortion=True),
        seed=7,
        workers=2,
    )
    assert np.array_equal(read_frame(par, par.frames[1]), img)
    assert json.loads(truth_path(par.folder).read_text())["levels_true_mm"] == truth["levels_true_mm"]
    # no distortion in the frames -> no distortion in scan.json
    s2 = render_scan("cone", tmp_path / "s2", levels=[10.0])
    assert np.allclose(load_scan(s2.folder).camera.dist, 0)


def test_virtual_camera_renders_the_level_at_capture_time():
    level = {"mm": 20.0}
    cam = VirtualCamera("cone", level_mm=lambda: level["mm"])
    assert isinstance(cam, Camera)
    a = cam.capture()
    level["mm"] = 5.0
    b = cam.capture()
    assert cam.last_level_mm == 5.0
    bright = lambda im: int((im[..., 1] > 100).sum())
    assert bright(b) > 3 * bright(a) > 0  # more of the cone stands out of the ink
    assert np.allclose(cam.camera_model().dist, 0)  # clean frames carry no distortion
    assert np.allclose(
        VirtualCamera("cone", level_mm=lambda: 1.0, effects="realistic").camera_model().dist,
        Rig().dist_coeffs(),
    )


def test_virtual_camera_ripple_settles():
    t = {"now": 0.0}
    level = {"mm": 10.0}
    fx = Effects(ripple_mm=0.3, ripple_decay_s=0.5)
    cam = VirtualCamera("cone", level_mm=lambda: level["mm"], effects=fx, clock=lambda: t["now"])
    settled = cam.capture()  # first frame: long settled
    level["mm"] = 10.0 + 1e-3  # a move (tiny, so the part hardly changes)
    t["now"] = 100.0
    ringing = cam.capture()
    assert cam.last_ripple_age_s == 0.0
    t["now"] = 105.0
    later = cam.capture()
    d_ring = np.abs(ringing.astype(int) - settled.astype(int)).sum()
    d_later = np.abs(later.astype(int) - settled.astype(int)).sum()
    assert d_ring > 20 * max(d_later, 1)


def test_cli_render(tmp_path, capsys):
    out = tmp_path / "s4"
    rc = main(
        [
            "render",
            "sample4",
            "-o",
            str(out),
            "--step",
            "10",
            "--effects",
            "realistic",
            "--seed",
            "3",
            "--quiet",
        ]
    )
    assert rc == 0
    scan = load_scan(out)
    assert len(scan.frames) == 4 and truth_path(out).is_file()
    assert "4 frames" in capsys.readouterr().out
    assert main(["render", "sample4", "-o", str(tmp_path / "x"), "--step", "0", "--quiet"]) == 2


def test_tank_is_written_only_when_the_bench_displaces_ink(tmp_path):
    """Processing corrects levels for displaced ink whenever scan.json names the tank."""
    render_scan("cone", tmp_path / "dry", levels=[10.0], effects=Effects(), seed=1)
    assert "tank" not in load_scan(tmp_path / "dry").extra


def test_the_render_loop_refines_a_step_in_which_a_face_came_out_at_once_as_the_runner_does(tmp_path):
    """Two passes: the plan's levels, then what vision/refine.py asks for from the part masks
    of those frames (the runner's rule, daemon/runner.py), rendered and asked again."""
    from appliance.sim.fakes import small_rig
    from appliance.sim.scanrender import refine_scan
    from appliance.vision.part import find_part
    from appliance.vision.refine import face_bracket, mask_pixel_mm, surfaced_faces

    folder = tmp_path / "plateau"
    scan = render_scan(
        "plateau", folder, levels=[26.0, 24.0, 22.0], rig=small_rig(320, 240), seed=2, refine_mm=0.1
    )
    extra = [f for f in scan.frames if "refines" in f.extra]
    # the flat top (25 mm) came out between 26 and 24; the shoulders below it did not come out at once
    assert len(extra) == 5 and all(f.extra["refines"] == [26.0, 24.0] for f in extra)
    assert extra[0].level_mm == 25.0
    part = {f.file: find_part(read_frame(scan, f), scan.camera, f.level_mm) for f in scan.frames}
    above, below = scan.frames[0], scan.frames[1]
    faces = surfaced_faces(
        part[above.file], part[below.file], mask_pixel_mm(scan.camera, part[below.file].shape)
    )
    lo, hi = face_bracket(faces[0], 26.0, 24.0, [(f.level_mm, part[f.file]) for f in extra])
    assert hi - lo <= 0.1 and 24.9 <= lo < hi <= 25.1  # a clean ink: the face is at 25 mm
    truth = json.loads(truth_path(folder).read_text())
    assert [f["file"] for f in truth["frames"]] == [f.file for f in scan.frames]
    assert refine_scan("plateau", folder, 0.1, rig=small_rig(320, 240), seed=2) == 0  # done is done
