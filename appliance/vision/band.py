"""The band of tiles where the waterline can be, and 8-bit work on just those tiles.

Between two levels of a scan the waterline moves a few pixels, so after the
first frame only a band of square tiles around last frame's contour is read:
the tiles are gathered (each with a one-pixel apron, so a 3x3 median inside a
tile sees true neighbours) side by side into one short, wide strip, filtered
and thresholded there in two OpenCV calls, and scattered back into the
full-frame buffers. The rest of the binary image keeps last frame's labels.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import as_strided


class TileGrid:
    """Square tiles of side `tile` covering the region of interest, `apron` pixels in from its edge.

    Each tile is read with an apron of `apron` pixels so that the 3x3 median
    (1 px) sees true neighbours.
    """

    def __init__(self, roi, tile: int, apron: int = 1):
        x0, y0, x1, y1 = roi
        self.tile = tile
        self.apron = apron
        self.ox, self.oy = x0 + apron, y0 + apron
        self.nx = max(0, (x1 - x0 - 2 * apron) // tile)
        self.ny = max(0, (y1 - y0 - 2 * apron) // tile)

    @property
    def shape(self):
        return (self.ny, self.nx)

    @property
    def covered(self):
        """(x0, y0, x1, y1) of the pixels the tiles cover."""
        return (self.ox, self.oy, self.ox + self.nx * self.tile, self.oy + self.ny * self.tile)

    def _offsets(self, margin):
        # steps of at most one tile, so every tile between the corners is hit
        return np.linspace(-margin, margin, int(np.ceil(2 * margin / self.tile)) + 1)

    def _tiles(self, pts, margin):
        T = self.tile
        offs = self._offsets(margin)
        txs = [np.floor((pts[:, 0] + d - self.ox) / T).astype(np.intp) for d in offs]
        tys = [np.floor((pts[:, 1] + e - self.oy) / T).astype(np.intp) for e in offs]
        for tx in txs:
            for ty in tys:
                yield ty, tx

    @staticmethod
    def _thin(pts, margin, every=4):
        """Every 4th point of a chain (<= 1.5 px apart) with the margin grown to match."""
        if len(pts) > 4 * every:
            return pts[::every], margin + 0.75 * every
        return pts, margin

    def mark(self, mask: np.ndarray, pts: np.ndarray, margin: float, thin=True):
        """Set every tile that a square of half-side `margin` around any point touches.

        With `thin`, `pts` is a chain of contour pixels (consecutive points at
        most 1.5 px apart) and only every 4th is used, with the margin grown.
        """
        if thin:
            pts, margin = self._thin(pts, margin)
        for ty, tx in self._tiles(pts, margin):
            ok = (tx >= 0) & (tx < self.nx) & (ty >= 0) & (ty < self.ny)
            mask[ty[ok], tx[ok]] = True
        return mask

    def all_marked(self, mask: np.ndarray, pts: np.ndarray, margin: float) -> bool:
        """Do the tiles around every point (within `margin`) all belong to `mask`?"""
        pts, margin = self._thin(pts, margin)
        for ty, tx in self._tiles(pts, margin):
            ok = (tx >= 0) & (tx < self.nx) & (ty >= 0) & (ty < self.ny)
            if not ok.all() or not mask[ty, tx].all():
                return False
        return True

    def gather(self, image: np.ndarray, ty: np.ndarray, tx: np.ndarray) -> np.ndarray:
        """Tiles (with their apron) of a 2-D uint8 image side by side: (A, n*A), A = tile + 2 apron.

        A strided view puts the tile row first, so one fancy-indexed copy lays
        the tiles out as one short, wide strip (wide rows keep OpenCV's
        filters fast) without a second transposing copy.
        """
        T, a = self.tile, self.apron
        A = T + 2 * a
        s0, s1 = image.strides
        base = image[self.oy - a :, self.ox - a :]
        view = as_strided(
            base, shape=(A, self.ny, self.nx, A), strides=(s0, s0 * T, s1 * T, s1), writeable=False
        )
        return view[:, ty, tx].reshape(A, -1)

    def scatter(self, strip: np.ndarray, dst: np.ndarray, ty: np.ndarray, tx: np.ndarray):
        """Write the inner tile x tile of each strip tile back into the full-size `dst`."""
        T, a = self.tile, self.apron
        A = T + 2 * a
        n = len(ty)
        inner = strip.reshape(A, n, A)[a:-a, :, a:-a].transpose(1, 0, 2)  # (n, T, T)
        x0, y0, x1, y1 = self.covered
        dst[y0:y1, x0:x1].reshape(self.ny, T, self.nx, T)[ty, :, tx, :] = inner
