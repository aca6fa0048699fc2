"""A small status display: SSD1306 128 x 64 OLED over I2C (smbus2).

Four lines of text (state, level, progress, IP address) in a 5 x 7 font
scaled to 8 x 16 cells: 16 characters a line. The frame is drawn in numpy
and sent page by page; the controller keeps the picture, so the daemon only
redraws when the text changes.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import DeviceError
from .base import Display

WIDTH, HEIGHT = 128, 64
_INIT = [
    0xAE,
    0xD5,
    0x80,
    0xA8,
    0x3F,
    0xD3,
    0x00,
    0x40,
    0x8D,
    0x14,
    0x20,
    0x00,
    0xA1,
    0xC8,
    0xDA,
    0x12,
    0x81,
    0x8F,
    0xD9,
    0xF1,
    0xDB,
    0x40,
    0xA4,
    0xA6,
    0xAF,
]


def render_lines(lines: list[str]) -> np.ndarray:
    """The 128 x 64 picture of up to four lines, 1 = lit."""
    img = np.zeros((HEIGHT, WIDTH), np.uint8)
    for i, text in enumerate(lines[:4]):
        cv2.putText(img, str(text)[:18], (0, 13 + 16 * i), cv2.FONT_HERSHEY_PLAIN, 0.9, 1, 1)
    return img


def to_pages(img: np.ndarray) -> bytes:
    """SSD1306 page layout: 8 pages of 128 bytes, bit k of a byte = row 8*page + k."""
    bits = img.reshape(HEIGHT // 8, 8, WIDTH).astype(np.uint8)
    weights = (1 << np.arange(8, dtype=np.uint8))[None, :, None]
    return (bits * weights).sum(axis=1).astype(np.uint8).tobytes()


class Ssd1306(Display):
    def __init__(self, bus: int = 1, address: int = 0x3C):
        from smbus2 import SMBus

        self.where = f"display i2c-{bus} 0x{address:02x}"
        self.address = address
        try:
            self._bus = SMBus(bus)
            self._command(_INIT)
        except OSError as e:
            raise DeviceError(self.where, f"no SSD1306 answers: {e}") from None
        self._last = None

    def _command(self, cmds):
        for c in cmds:
            self._bus.write_byte_data(self.address, 0x00, c)

    def show(self, lines: list[str]) -> None:
        if lines == self._last:
            return
        data = to_pages(render_lines(lines))
        try:
            self._command([0x21, 0, WIDTH - 1, 0x22, 0, HEIGHT // 8 - 1])
            for i in range(0, len(data), 16):  # SMBus blocks are at most 32 bytes
                self._bus.write_i2c_block_data(self.address, 0x40, list(data[i : i + 16]))
        except OSError as e:
            raise DeviceError(self.where, f"write failed: {e}") from None
        self._last = list(lines)

    def close(self):
        try:
            self._command([0xAE])  # display off
        except OSError:
            pass
        self._bus.close()
