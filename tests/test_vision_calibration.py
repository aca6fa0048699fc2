"""Calibration end to end on chessboards drawn through a known camera (with distortion).

The renderer team's sim/boards.py will render these on the virtual bench; until
then this file draws its own: each pixel's ray (through the true K and lens
distortion) meets the board plane, and the checker is anti-aliased analytically.
"""

import json

import cv2
import numpy as np
import pytest

from appliance.cli import main as cli_main
from appliance.vision.calibration import (
    Board,
    BoardPose,
    CalibrationError,
    calibrate,
    find_corners,
    plane_points,
)
from appliance.vision.camera import CameraModel

W, H = 800, 600
K = np.array([[700.0, 0, 404.0], [0, 700.0, 297.0], [0, 0, 1]])
DIST = np.array([-0.08, 0.05, 2e-4, -1e-4, 0.0])
BOARD = Board(9, 6, 20.0)
POSE = BoardPose(-60.0, 50.0, 0.0)
CAMERA_C = np.array([10.0, -5.0, 300.0])  # camera centre over the liquid plane (mm)
MM_PER_PX = 300.0 / 700.0


def _rot(ax, ay, az):
    return (
        cv2.Rodrigues(np.array([ax, 0, 0.0]))[0]
        @ cv2.Rodrigues(np.array([0, ay, 0.0]))[0]
        @ cv2.Rodrigues(np.array([0, 0, az]))[0]
    )


R_DOWN = _rot(0.01, -0.008, 0.012) @ np.diag([1.0, -1.0, -1.0])  # plane -> camera, looking down


def rays(K, dist, size):
    """Unit-depth ray (x, y, 1) of every pixel of a distorted image."""
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    n = cv2.undistortPoints(np.column_stack([u.ravel(), v.ravel()]).reshape(-1, 1, 2), K, dist)
    return np.column_stack([n.reshape(-1, 2), np.ones(u.size)])


RAYS = rays(K, DIST, (W, H))


def draw_board(R, t, to_board, rays_=None, size=(W, H), focal=700.0, board=BOARD):
    """Image of the plane {z = 0} of frame (R, t) (X_cam = R X + t); to_board maps plane xy -> board mm."""
    rays_ = RAYS if rays_ is None else rays_
    n = R[:, 2]
    s = (n @ t) / (rays_ @ n)
    X = rays_ * s[:, None] - t
    p = X @ R  # R^T (X - t)
    bx, by = to_board(p[:, 0], p[:, 1])
    pix = np.abs(s) / focal  # mm per pixel on the board, roughly
    sq = board.square_mm
    gx = np.clip(np.sin(np.pi * bx / sq) * sq / np.pi / pix, -1, 1)
    gy = np.clip(np.sin(np.pi * by / sq) * sq / np.pi / pix, -1, 1)
    inside = (bx > -sq) & (bx < board.cols * sq) & (by > -sq) & (by < board.rows * sq) & (s > 0)
    val = np.where(inside, 128 + 100 * gx * gy, 228.0)
    return np.clip(np.rint(val), 0, 255).astype(np.uint8).reshape(size[1], size[0])


def pose_to_board(pose):
    a = np.radians(pose.angle_deg)
    along, down = np.array([np.cos(a), np.sin(a)]), np.array([np.sin(a), -np.cos(a)])

    def to_board(x, y):
        d = np.column_stack([x - pose.x0, y - pose.y0])
        return d @ along, d @ down

    return to_board


def tilted_views():
    """Nine views that together reach every part of the image (the lens model is only
    as good as the field its corners covered)."""
    out = []
    rng = np.random.default_rng(7)
    for cx in (-0.45, 0.0, 0.45):
        for cy in (-0.35, 0.0, 0.35):
            ax, ay, az = rng.uniform(-0.3, 0.3, 3)
            R = _rot(ax, ay, az)
            z = 400.0
            # put the board's centre where the ray through (cx, cy) of the half-field meets z
            centre = np.array([cx * z * 404 / 700, cy * z * 297 / 700, z])
            t = centre - R @ np.array([80.0, 50.0, 0.0])
            out.append(draw_board(R, t, lambda x, y: (x, y)))
    return out


def plane_view():
    return draw_board(R_DOWN, -R_DOWN @ CAMERA_C, pose_to_board(POSE))


def true_camera():
    P = K @ np.column_stack([R_DOWN[:, 0], R_DOWN[:, 1], -R_DOWN @ CAMERA_C])
    Hm = np.linalg.inv(P / P[2, 2])
    return CameraModel(W, H, Hm / Hm[2, 2], K, DIST, CAMERA_C[2])


@pytest.fixture(scope="module")
def views():
    return tilted_views(), plane_view()


def field_error_mm(cam_json):
    """Max distance (mm) between where the calibration and the truth put each pixel on the plane."""
    truth = true_camera()
    est = CameraModel(
        cam_json["width"],
        cam_json["height"],
        np.array(cam_json["homography"]),
        np.array(cam_json["K"]),
        np.array(cam_json["dist"]),
    )
    u, v = np.meshgrid(np.linspace(20, W - 20, 25), np.linspace(20, H - 20, 19))
    uv = np.column_stack([u.ravel(), v.ravel()])
    return np.abs(est.pixels_to_mm(uv) - truth.pixels_to_mm(uv)).max()


def test_corners_are_ordered_from_the_top_left_and_land_on_the_pose(views):
    _, plane = views
    c = find_corners(plane, BOARD)
    assert c[0].sum() < c[-1].sum()
    xy = true_camera().pixels_to_mm(c)
    assert np.abs(xy - plane_points(BOARD, POSE)).max() < 0.05


@pytest.mark.slow
def test_rendered_boards_recover_the_plane_within_20_microns(views):
    boards, plane = views
    cam, report = calibrate(boards, plane, BOARD, POSE)
    assert set(cam) == {"width", "height", "homography", "K", "dist", "height_mm"}
    assert report["reprojection_rms_px"] < 0.1
    np.testing.assert_allclose(np.array(cam["K"]), K, rtol=2e-3, atol=1.0)
    assert cam["height_mm"] == pytest.approx(300.0, abs=0.5)
    err = field_error_mm(cam)
    # This small test camera sees 0.43 mm per pixel; the bench's sees 0.079. The
    # target (0.02 mm on the bench = 0.25 px) is checked in pixels of the field.
    err_px = err / MM_PER_PX
    print(
        f"calibration: max field error {err * 1000:.1f} um = {err_px:.3f} px "
        f"= {err_px * 0.079 * 1000:.1f} um at the bench's 0.079 mm/px"
    )
    assert err_px * 0.079 < 0.02


def test_no_board_and_mixed_sizes_are_clear_errors(views):
    boards, plane = views
    with pytest.raises(CalibrationError, match="not found"):
        calibrate(boards[:3] + [np.full((H, W), 128, np.uint8)], plane, BOARD, POSE)
    with pytest.raises(CalibrationError, match="same camera"):
        calibrate(boards[:3] + [cv2.resize(boards[3], (640, 480))], plane, BOARD, POSE)


def _write(folder, views):
    boards, plane = views
    paths = []
    for k, img in enumerate(boards):
        p = folder / f"board{k}.png"
        cv2.imwrite(str(p), img)
        paths.append(str(p))
    cv2.imwrite(str(folder / "plane.png"), plane)
    return paths


@pytest.mark.slow
def test_calibrate_command_writes_the_camera_block_and_keeps_the_previous(tmp_path, views, monkeypatch):
    monkeypatch.setenv("INKSLICE_DATA", str(tmp_path / "data"))
    paths = _write(tmp_path, views)
    args = [
        "calibrate",
        *paths,
        "--plane",
        str(tmp_path / "plane.png"),
        "--pattern",
        "9x6",
        "--square-mm",
        "20",
        "--board-origin",
        "-60",
        "50",
    ]
    assert cli_main(args) == 0
    out = tmp_path / "data" / "calibration.json"
    first = json.loads(out.read_text())
    assert first["width"] == W and len(first["dist"]) == 5
    assert field_error_mm(first) / MM_PER_PX * 0.079 < 0.02
    # a second calibration keeps the first one as calibration.prev.json
    assert cli_main(args) == 0
    assert json.loads((tmp_path / "data" / "calibration.prev.json").read_text()) == first
    # a bad run (board not found) leaves both files untouched
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((H, W), 128, np.uint8))
    before = out.read_bytes(), (tmp_path / "data" / "calibration.prev.json").read_bytes()
    assert (
        cli_main(
            [
                "calibrate",
                *paths[:3],
                str(blank),
                "--plane",
                str(tmp_path / "plane.png"),
                "--pattern",
                "9x6",
                "--square-mm",
                "20",
            ]
        )
        == 2
    )
    assert (out.read_bytes(), (tmp_path / "data" / "calibration.prev.json").read_bytes()) == before


@pytest.mark.slow
def test_a_rendered_frame_measures_as_well_with_our_calibration_as_with_the_true_one():
    """End to end on the virtual bench's rig (scaled to 640 x 480): boards drawn through its
    true lens and pose, calibrated, then a rendered frame with lens distortion measured."""
    from appliance.sim import surfaces
    from appliance.sim.fakes import small_rig
    from appliance.sim.render import Effects, render_frame
    from appliance.vision.pipeline import WaterlineExtractor

    rig = small_rig(640, 480)
    size, Kr, dr = (640, 480), rig.K(), rig.dist_coeffs()
    r = rays(Kr, dr, size)
    board = Board(9, 6, 10.0)
    rng = np.random.default_rng(11)
    views = []
    for cx in (-0.35, 0.0, 0.35):
        for cy in (-0.3, 0.0, 0.3):
            R = _rot(*rng.uniform(-0.3, 0.3, 3))
            z = 330.0
            centre = np.array([cx * z * 320 / Kr[0, 0], cy * z * 240 / Kr[0, 0], z])
            views.append(
                draw_board(
                    R, centre - R @ np.array([40.0, 25.0, 0.0]), lambda x, y: (x, y), r, size, Kr[0, 0], board
                )
            )
    pose = BoardPose(10.0, 80.0, 0.0)
    Rc = rig.rotation()
    plane = draw_board(Rc, -Rc @ rig.centre, pose_to_board(pose), r, size, Kr[0, 0], board)
    cam_json, _ = calibrate(views, plane, board, pose)
    ours = CameraModel(
        640,
        480,
        np.array(cam_json["homography"]),
        np.array(cam_json["K"]),
        np.array(cam_json["dist"]),
        cam_json["height_mm"],
    )
    truth = rig.camera_model(distorted=True)
    surf = surfaces.get("sample1")
    frame = render_frame(surf, 25.0, rig, Effects(lens_distortion=True), np.random.default_rng(0))
    mm_px = rig.height_mm / Kr[0, 0]
    out = {}
    for name, cam in (("truth", truth), ("ours", ours)):
        pts = WaterlineExtractor(cam).extract(frame, 25.0).points
        e = np.abs(surf.level_sdf(pts[:, 0], pts[:, 1], 25.0)) / mm_px
        out[name] = float(np.sqrt(np.mean(e**2)))
    print(
        f"rendered frame RMS: true calibration {out['truth']:.3f} px, ours {out['ours']:.3f} px "
        f"({mm_px:.3f} mm/px)"
    )
    assert out["truth"] < 0.1
    assert out["ours"] < out["truth"] + 0.05
