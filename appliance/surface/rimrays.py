"""The ray over a hidden wall's rim: a ceiling for what stands behind it.

A wall facing away from the camera is hidden by its own top edge, and the ink's edge the
camera sees beyond it is where the ray from the camera over that rim meets the ink. The
ray is empty from the camera down to that ink, or the camera would have seen the part
there instead: whatever stands behind the rim stands under it. Over a point q, at rho
from the camera's foot, a ray that meets the ink t further out along the line from the
foot through q stands H t / (rho + t) above the ink, H the camera's height over it.

Every frame below the rim sees the same ray (the camera and the rim stay where they are),
landing further out as the ink falls. Read from the frames, the rays over one node still
spread: on the stepped block's 85 deg wall, over a node 26.15 mm high, two frames' rays
passed at 26.7-26.8 mm and the eight below them at 28.5-29.1 (where they land, 0.1-0.2 mm
further out than one ray would). A ceiling too low cuts the part, so a node's ceiling is the
highest of its frames' rays. Taking the lowest, 40 of the blade's cells stood more than
0.5 mm under the true part (22 without the rays); with the highest, 23.
"""

from __future__ import annotations

import numpy as np

from .slices import Slice

SEEN_TOL_MM = 0.05  # a node counts as in the ink or out of it this far from the waterline (a pixel)
GRAZING = 0.3  # a line from the camera's foot meeting the waterline more obliquely (cosine) says nothing


def under_rim_rays(q: np.ndarray, seen: list[Slice], corrected: list[Slice], camera, reach: float):
    """Per point of `q` (N, 2), the highest of the frames' rays over a rim that pass over
    it (inf: none). `seen`: the frames as the camera saw them; `corrected`: the same points
    with the walls' rims put back (Slice.edge marks them); `camera`: the Perspective; a
    frame's rim counts for a point when the camera saw it within `reach` of the point."""
    if camera is None or len(q) == 0:
        return np.full(len(q), np.inf)
    highest = np.full(len(q), -np.inf)
    for s, c in zip(seen, corrected):
        if s.empty or c.edge is None or len(c.edge) != len(s.P) or not c.edge.any():
            continue
        d, i = s.tree.query(q, distance_upper_bound=reach)
        near = np.flatnonzero(np.isfinite(d))
        near = near[c.edge[i[near]]]
        if near.size == 0:
            continue
        cam = camera.over(s)
        t, rho = _out_along_ray(s, q[near], i[near], np.asarray(cam.xy, float), c.edge)
        ok = np.isfinite(t)
        t = t[ok] + SEEN_TOL_MM
        at = near[ok]
        highest[at] = np.maximum(highest[at], c.level + cam.height_mm * t / (rho[ok] + t))
    return np.where(np.isfinite(highest), highest, np.inf)


def _out_along_ray(s: Slice, q: np.ndarray, i: np.ndarray, C: np.ndarray, rim: np.ndarray):
    """How far out from each q, along the line from the camera's foot C through it, that
    line crosses the waterline at a rim (inf where it does not near vertex i, crosses
    behind q, or meets it grazing), and q's distance from C. The crossing is found on the
    waterline's tangent at the vertex nearest to it, twice over: the vertex nearest to q
    is where the waterline is nearest, not where the line from the camera meets it."""
    rho = np.hypot(*(q - C).T)
    u = (q - C) / np.maximum(rho, 1e-9)[:, None]
    for _ in range(2):
        tangent = s.P[s.nxt[i]] - s.P[s.prv[i]]
        normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
        normal /= np.maximum(np.hypot(*normal.T), 1e-12)[:, None]
        cos = np.einsum("ij,ij->i", u, normal)
        ahead = np.einsum("ij,ij->i", s.P[i] - q, normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ahead / cos
        t = np.where((np.abs(cos) >= GRAZING) & (t >= 0.0), t, np.inf)
        gap, i = s.tree.query(q + np.where(np.isfinite(t), t, 0.0)[:, None] * u)
    step = np.hypot(*(s.P[s.nxt[i]] - s.P[i]).T) + np.hypot(*(s.P[s.prv[i]] - s.P[i]).T)
    ok = np.isfinite(t) & (gap <= step + SEEN_TOL_MM) & rim[i]
    return np.where(ok, t, np.inf), rho
