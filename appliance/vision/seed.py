"""The seed method's image pipeline (the dissertation's figure 4-21): our baseline.

read image -> grayscale -> 3x3 median -> threshold -> binary -> Canny edges
-> (x, y) of every edge pixel -> a slice at the frame's level.

The dissertation thresholded by eye; we use Otsu, the automatic choice closest
to what it did. Edge pixels are whole pixels: this is what caps its accuracy
at about a third of a pixel, against the sub-pixel waterlines of pipeline.py.
Points are mapped to mm through the scan's calibration (the dissertation had
none; using ours isolates the pipeline's own error from the optics').
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera import CameraModel


@dataclass
class SeedSlice:
    level_mm: float
    edges_mm: np.ndarray  # (N, 2) edge pixel centres mapped to the liquid plane
    binary: np.ndarray  # uint8 0/255, the thresholded frame (part = 255)


def binarise(frame: np.ndarray) -> np.ndarray:
    gray = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    smooth = cv2.medianBlur(gray, 3)
    _, binary = cv2.threshold(smooth, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return binary


def edge_pixels(binary: np.ndarray) -> np.ndarray:
    """(N, 2) array of (u, v) pixel coordinates of Canny edges of the binary image."""
    edges = cv2.Canny(binary, 50, 150)
    v, u = np.nonzero(edges)
    return np.column_stack([u, v]).astype(np.float64)


def seed_slice(frame: np.ndarray, level_mm: float, camera: CameraModel) -> SeedSlice:
    binary = binarise(frame)
    return SeedSlice(level_mm, camera.pixels_to_mm(edge_pixels(binary)), binary)


def exposed_at(binary: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Is the part above the liquid at these (distorted) pixel positions? Nearest pixel."""
    h, w = binary.shape
    u = np.clip(np.rint(pixels[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.rint(pixels[:, 1]).astype(int), 0, h - 1)
    inside = (
        (pixels[:, 0] >= -0.5) & (pixels[:, 0] < w - 0.5) & (pixels[:, 1] >= -0.5) & (pixels[:, 1] < h - 0.5)
    )
    return (binary[v, u] > 0) & inside
