"""The printable calibration chessboard: the shipped PDF and PNG are the board the
calibration looks for, at the size the wizard states."""

import re
from pathlib import Path

import cv2
import numpy as np
from web_helpers import login, make_app

from appliance.daemon.calibration import BOARD
from appliance.vision.calibration import find_corners
from appliance.vision.printboard import (
    PT_PER_MM,
    board_image,
    board_pdf,
    board_png,
    describe,
    printed_size_mm,
)

STATIC = Path(__file__).resolve().parents[1] / "appliance" / "web" / "static"


def test_the_shipped_files_are_what_the_board_geometry_gives():
    # regenerate with `python -m appliance.vision.printboard` after changing BOARD
    assert (STATIC / "chessboard.pdf").read_bytes() == board_pdf(BOARD)
    shipped = cv2.imdecode(
        np.frombuffer((STATIC / "chessboard.png").read_bytes(), np.uint8), cv2.IMREAD_GRAYSCALE
    )
    assert np.array_equal(shipped, board_image(BOARD))


def test_the_png_prints_at_300_dpi_and_the_detector_finds_the_board_at_10_mm_a_square():
    png = (STATIC / "chessboard.png").read_bytes()
    assert png == board_png(BOARD)
    i = png.index(b"pHYs")
    ppm_x, ppm_y, unit = (
        int.from_bytes(png[i + 4 : i + 8], "big"),
        int.from_bytes(png[i + 8 : i + 12], "big"),
        png[i + 12],
    )
    assert unit == 1 and ppm_x == ppm_y == round(300 / 0.0254)
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
    corners = find_corners(img, BOARD).reshape(BOARD.rows, BOARD.cols, 2)
    px_per_mm = 300 / 25.4
    along_rows = np.linalg.norm(np.diff(corners, axis=1), axis=2) / px_per_mm
    along_cols = np.linalg.norm(np.diff(corners, axis=0), axis=2) / px_per_mm
    assert np.allclose(along_rows, BOARD.square_mm, atol=0.1) and np.allclose(
        along_cols, BOARD.square_mm, atol=0.1
    )


def test_the_pdf_is_an_a4_page_of_10_mm_squares_with_a_sound_cross_reference_table():
    pdf = (STATIC / "chessboard.pdf").read_bytes()
    assert pdf.startswith(b"%PDF-1.4\n") and pdf.endswith(b"%%EOF\n")
    # every xref entry points at its object, startxref at the table
    start = int(re.search(rb"startxref\n(\d+)\n", pdf).group(1))
    assert pdf[start : start + 5] == b"xref\n"
    offsets = [int(o) for o in re.findall(rb"^(\d{10}) 00000 n $", pdf, re.M)]
    assert len(offsets) == 5
    for n, off in enumerate(offsets, 1):
        assert pdf[off:].startswith(b"%d 0 obj" % n)
    length = int(re.search(rb"/Length (\d+) >>\nstream\n", pdf).group(1))
    body = pdf.split(b"stream\n", 1)[1]
    assert body[length:].startswith(b"\nendstream")
    w, h = (float(v) / PT_PER_MM for v in re.search(rb"/MediaBox \[0 0 ([\d.]+) ([\d.]+)\]", pdf).groups())
    assert abs(w - 210) < 0.01 and abs(h - 297) < 0.01
    # the drawing is in millimetres: 35 dark squares of 10 mm filling a 100 x 70 mm board
    assert f"{PT_PER_MM:.5f} 0 0 {PT_PER_MM:.5f} 0 0 cm".encode() in body
    rects = [tuple(map(float, m)) for m in re.findall(rb"([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+) re f", body)]
    squares = [r for r in rects if r[2] == r[3] == BOARD.square_mm]
    assert len(squares) == (BOARD.cols + 1) * (BOARD.rows + 1) // 2
    xs, ys = [r[0] for r in squares], [r[1] for r in squares]
    assert (max(xs) + 10 - min(xs), max(ys) + 10 - min(ys)) == printed_size_mm(BOARD) == (100.0, 70.0)
    bar = [r for r in rects if r[3] == 1.0]
    assert [r[2] for r in bar] == [50.0]  # the scale bar to check the print with


def test_the_calibration_page_states_the_printed_size_and_links_both_files(tmp_path):
    app, _ = make_app(tmp_path)
    c = app.test_client()
    login(c, app.config["FIRST_RUN_PASSWORD"])
    page = c.get("/calibration").get_data(as_text=True)
    assert describe(BOARD) in page and "100 x 70 mm" in page and "10 mm" in page
    for name in ("chessboard.pdf", "chessboard.png"):
        href = re.search(rf'href="([^"]*{name})"', page).group(1)
        r = c.get(href)
        assert r.status_code == 200 and r.data == (STATIC / name).read_bytes(), name


def test_the_commissioning_wizard_names_the_files_and_their_printed_size(tmp_path):
    from appliance.daemon.service import BenchService
    from appliance.sim.fakes import FakeBench

    svc = BenchService(tmp_path / "data", FakeBench("cone"))
    try:
        board = svc.commissioning()["board"]
    finally:
        svc.close()
    assert board["printed_mm"] == [100.0, 70.0] and board["print"] == describe(BOARD)
    assert all((STATIC / name).is_file() for name in board["files"]) and len(board["files"]) == 2
