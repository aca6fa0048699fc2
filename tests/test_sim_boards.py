"""Calibration images: OpenCV finds the board where the rig's true camera puts it,
and calibrating from them recovers the true camera model and homography."""

import json

import cv2
import numpy as np
import pytest

from appliance.sim.boards import DEFAULT_POSES, Board, render_calibration
from appliance.sim.rig import Rig


def _find(path, board):
    gray = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2GRAY)
    ok, c = cv2.findChessboardCorners(
        gray, (board.cols, board.rows), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    assert ok, f"{path.name}: board not found"
    c = cv2.cornerSubPix(
        gray, c, (7, 7), (-1, -1), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    ).reshape(-1, 2)
    return c


def _match_order(found, true):
    """Put the found corners in the true corners' order. findChessboardCorners may
    start from another corner of the board; here the errors are far below the
    square size, so the nearest true corner identifies each one."""
    d = np.linalg.norm(found[:, None, :] - true[None, :, :], axis=2)
    idx = np.argmin(d, axis=0)
    assert len(set(idx.tolist())) == len(true), "ambiguous corner match"
    return found[idx]


@pytest.fixture(scope="module")
def plane_only(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cal1") / "calibration"
    truth = render_calibration(folder, poses=())
    return folder, truth


def test_flat_board_gives_the_true_homography(plane_only):
    """Fast path: the board floating on the liquid, detected by OpenCV, with the true
    lens model: its corners sit at their true pixels and give the true homography."""
    folder, truth = plane_only
    board = Board()
    rig = Rig()
    im = truth["images"][0]
    assert im["kind"] == "plane"
    found = _match_order(_find(folder / "plane.png", board), np.array(im["corners_px"]))
    assert np.abs(found - np.array(im["corners_px"])).max() < 0.15
    doc = json.loads((folder / "board.json").read_text())
    und = cv2.undistortPoints(found.reshape(-1, 1, 2), rig.K(), rig.dist_coeffs(), None, None, rig.K())
    Hm, _ = cv2.findHomography(und.reshape(-1, 2), np.array(doc["plane"]["corners_xy_mm"]))
    Ht = rig.homography()
    uv = np.column_stack([np.linspace(500, 1500, 12), np.linspace(1100, 400, 12), np.ones(12)])
    a, b = uv @ Hm.T, uv @ Ht.T
    err = np.linalg.norm(a[:, :2] / a[:, 2:] - b[:, :2] / b[:, 2:], axis=1)
    assert err.max() < 0.01


@pytest.fixture(scope="module")
def calib(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cal") / "calibration"
    poses = DEFAULT_POSES[:7]
    truth = render_calibration(folder, poses=poses)
    return folder, truth


def test_truth_lives_outside_the_folder(plane_only):
    folder, truth = plane_only
    names = sorted(p.name for p in folder.iterdir())
    assert "board.json" in names and "plane.png" in names
    assert not any("truth" in n for n in names)
    doc = json.loads((folder.parent / "calibration.truth.json").read_text())
    assert np.allclose(doc["camera"]["K"], Rig().K())
    board = json.loads((folder / "board.json").read_text())
    assert board["board"]["inner_corners"] == [9, 6]


@pytest.mark.slow
def test_opencv_finds_corners_where_the_camera_puts_them(calib):
    folder, truth = calib
    board = Board()
    errs = []
    for im in truth["images"]:
        found = _match_order(_find(folder / im["file"], board), np.array(im["corners_px"]))
        errs.append(np.linalg.norm(found - np.array(im["corners_px"]), axis=1))
    errs = np.concatenate(errs)
    print(f"corner error: median {np.median(errs):.4f} px, max {errs.max():.4f} px")
    assert np.median(errs) < 0.05 and errs.max() < 0.2


@pytest.mark.slow
def test_calibration_recovers_the_camera_and_the_plane_homography(calib):
    folder, truth = calib
    board = Board()
    rig = Rig()
    obj, img = [], []
    for im in truth["images"]:
        if im["kind"] != "pose":
            continue
        found = _match_order(_find(folder / im["file"], board), np.array(im["corners_px"]))
        obj.append(board.object_points().astype(np.float32))
        img.append(found.astype(np.float32))
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, (rig.width, rig.height), None, None)
    print(f"calibrateCamera rms {rms:.4f} px, f {K[0, 0]:.1f} vs {rig.focal_px}")
    assert rms < 0.1
    assert abs(K[0, 0] / rig.focal_px - 1) < 0.01 and abs(K[1, 1] / rig.focal_px - 1) < 0.01
    # the flat board gives the homography. End to end, with the CALIBRATED K and
    # dist: liquid-plane points -> true distorted pixels -> calibrated undistortion
    # -> homography from the flat board's corners -> mm, against the truth.
    doc = json.loads((folder / "board.json").read_text())
    plane = [im for im in truth["images"] if im["kind"] == "plane"][0]
    found = _match_order(_find(folder / "plane.png", board), np.array(plane["corners_px"]))
    und = cv2.undistortPoints(found.reshape(-1, 1, 2), K, dist, None, None, K)
    Hm, _ = cv2.findHomography(und.reshape(-1, 2), np.array(doc["plane"]["corners_xy_mm"]))
    X, Y = np.meshgrid(np.linspace(15, 85, 8), np.linspace(15, 85, 8))
    Q = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    px = rig.project(Q, distorted=True)
    u = cv2.undistortPoints(px.reshape(-1, 1, 2), K, dist, None, None, K).reshape(-1, 2)
    a = np.column_stack([u, np.ones(len(u))]) @ Hm.T
    err = np.linalg.norm(a[:, :2] / a[:, 2:] - Q[:, :2], axis=1)
    pix = 0.079
    print(
        f"calibrated pipeline on the liquid plane (70 x 70 mm): max {err.max():.4f} mm "
        f"({err.max() / pix:.3f} px), rms {np.sqrt(np.mean(err**2)):.4f} mm"
    )
    assert err.max() < 0.5 * pix


@pytest.mark.slow
def test_the_same_board_images_give_the_same_camera_to_the_last_bit(calib):
    """Commissioning is repeatable: threaded, calibrateCamera summed in whatever order its
    threads finished, and K came out 1e-13 apart from one run to the next."""
    from appliance.vision import calibration

    folder, truth = calib
    b = Board()
    board = calibration.Board(b.cols, b.rows, b.square_mm)
    images = [cv2.imread(str(folder / im["file"])) for im in truth["images"] if im["kind"] == "pose"]
    threads = cv2.getNumThreads()
    runs = [calibration.intrinsics(images, board) for _ in range(4)]
    assert cv2.getNumThreads() == threads  # OpenCV's own setting is put back
    for r in runs[1:]:
        assert r.K.tobytes() == runs[0].K.tobytes() and r.dist.tobytes() == runs[0].dist.tobytes()
