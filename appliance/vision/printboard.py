"""The printable calibration chessboard, drawn from the board the calibration looks for.

The web UI offers it as a PDF (A4, the board centred, a 50 mm scale bar to
check the print with a ruler) and a PNG (300 dpi, with the resolution written
in the file so an image viewer prints it at its true size).  Both are shipped
in appliance/web/static/ and regenerated from the board's geometry, so the
print and the detector cannot disagree:

    python -m appliance.vision.printboard appliance/web/static

The PDF is written by hand (filled rectangles and a few words of Helvetica):
no PDF library for a page of squares.
"""

from __future__ import annotations

import struct
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np

from ..atomicio import write_bytes
from .calibration import Board

# The board the box's calibration looks for and the one printed for it: 9 x 6 inner
# corners, 10 mm squares (print at 100 %). Defined here, with its print, so the print
# and the detector cannot disagree; daemon/calibration.py takes it from here.
PRINTED = Board(9, 6, 10.0)
PT_PER_MM = 72 / 25.4
A4_MM = (210.0, 297.0)
PNG_DPI = 300
SCALE_BAR_MM = 50.0


def squares(board: Board) -> tuple[int, int]:
    """Squares across and down: one more than the inner corners."""
    return board.cols + 1, board.rows + 1


def printed_size_mm(board: Board) -> tuple[float, float]:
    nx, ny = squares(board)
    return nx * board.square_mm, ny * board.square_mm


def describe(board: Board) -> str:
    """The sentence the wizard shows: what to print and how big it must come out."""
    (nx, ny), (w, h) = squares(board), printed_size_mm(board)
    return (
        f"{nx} x {ny} squares of {board.square_mm:g} mm, {w:g} x {h:g} mm in all: "
        f"print at 100 % (no fit to page) and check a square with a ruler"
    )


def _dark_squares(board: Board):
    """(column, row) of the dark squares, row 0 at the top; the top-left one is dark."""
    nx, ny = squares(board)
    return [(i, j) for j in range(ny) for i in range(nx) if (i + j) % 2 == 0]


def board_pdf(board: Board) -> bytes:
    w, h = printed_size_mm(board)
    x0, top = (A4_MM[0] - w) / 2, (A4_MM[1] + h) / 2  # PDF's y axis points up
    s = board.square_mm
    ops = ["q", f"{PT_PER_MM:.5f} 0 0 {PT_PER_MM:.5f} 0 0 cm", "0 g"]
    ops += [f"{x0 + i * s:.3f} {top - (j + 1) * s:.3f} {s:.3f} {s:.3f} re f" for i, j in _dark_squares(board)]
    bar_y = top - h - 15
    ops += [
        f"{x0:.3f} {bar_y:.3f} {SCALE_BAR_MM:.3f} 1 re f",  # the scale bar
        f"{x0:.3f} {bar_y - 2:.3f} 0.3 5 re f",
        f"{x0 + SCALE_BAR_MM - 0.3:.3f} {bar_y - 2:.3f} 0.3 5 re f",
        "Q",
    ]
    lines = [
        (top + 12, 14, "InkSlice calibration board"),
        (top + 6, 10, describe(board)[:1].upper() + describe(board)[1:] + "."),
        (bar_y - 7, 10, f"This bar is {SCALE_BAR_MM:g} mm long when printed at the right size."),
        (bar_y - 13, 10, "Lay it flat on the base, squares up, when the wizard asks for it."),
    ]
    for y_mm, size, text in lines:
        esc = text.replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)")
        ops.append(f"BT /F1 {size} Tf {x0 * PT_PER_MM:.2f} {y_mm * PT_PER_MM:.2f} Td ({esc}) Tj ET")
    content = "\n".join(ops).encode("ascii")
    page_w, page_h = (v * PT_PER_MM for v in A4_MM)
    objects = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        (
            f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {page_w:.2f} {page_h:.2f}] /Contents 4 0 R "
            f"/Resources << /Font << /F1 5 0 R >> >> >>"
        ).encode(),
        b"<< /Length %d >>\nstream\n" % len(content) + content + b"\nendstream",
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>",
    ]
    out = bytearray(b"%PDF-1.4\n")
    offsets = []
    for n, body in enumerate(objects, 1):
        offsets.append(len(out))
        out += b"%d 0 obj\n" % n + body + b"\nendobj\n"
    xref = len(out)
    out += b"xref\n0 %d\n0000000000 65535 f \n" % (len(objects) + 1)
    out += b"".join(b"%010d 00000 n \n" % o for o in offsets)
    out += b"trailer\n<< /Size %d /Root 1 0 R >>\nstartxref\n%d\n%%%%EOF\n" % (len(objects) + 1, xref)
    return bytes(out)


def board_image(board: Board, dpi: int = PNG_DPI) -> np.ndarray:
    """The board on white with one square of margin all round, grey levels, `dpi` pixels per inch."""
    px = dpi / 25.4
    w, h = printed_size_mm(board)
    m = board.square_mm
    img = np.full((round((h + 2 * m) * px), round((w + 2 * m) * px)), 255, np.uint8)
    edge = lambda mm: round((m + mm) * px)
    for i, j in _dark_squares(board):
        s = board.square_mm
        img[edge(j * s) : edge((j + 1) * s), edge(i * s) : edge((i + 1) * s)] = 0
    return img


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def board_png(board: Board, dpi: int = PNG_DPI) -> bytes:
    ok, encoded = cv2.imencode(".png", board_image(board, dpi))
    assert ok
    png = encoded.tobytes()
    ppm = round(dpi / 0.0254)
    phys = _chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1))  # unit 1: pixels per metre
    ihdr_end = 8 + 8 + 13 + 4  # signature, IHDR length+type, data, CRC
    return png[:ihdr_end] + phys + png[ihdr_end:]


def write_files(folder, board: Board = PRINTED) -> list[Path]:
    folder = Path(folder)
    out = [folder / "chessboard.pdf", folder / "chessboard.png"]
    write_bytes(out[0], board_pdf(board))
    write_bytes(out[1], board_png(board))
    return out


if __name__ == "__main__":
    for p in write_files(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parents[1] / "web" / "static"):
        print(p)
