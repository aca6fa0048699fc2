"""Where a face meets a wall at a sharp edge: what the top's solve takes across it.

The contact line pins at a sharp edge, so the rise jumps there: a face flatter than the
contact angle keeps its own (a depression, for an ink that dewets) right up to the edge,
and the wall below has the wall's. The meniscus solve (contact_lines.py) reads the top's
slope by central differences and smooths over third differences; both reach over such an
edge and carry the wall's rise onto the face. These find the edges on the apparent surface
and hold the face's last node to its own side.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import ndimage

from .lattice import fill_nearest, steepness

# steeper (63 deg) on one side of a level node than this, that side is over an edge. A smooth
# shoulder that reaches 45 deg one lattice node off its flat top is none: taken for one at 1.0,
# tests/test_surface_summit.py's mesa went from 0.31 to 0.35 mm off on average
EDGE_SLOPE = 2.0
# near a wall inside the part the top's slope is read within this of A's (a fraction of it, plus
# a slope), that many solve-lattice nodes from the wall's
SLOPE_PLAY = (0.3, 0.1)
WALL_REACH = 6


def slopes_held_at_edges(problem, A, trusted, level_slope, exposed=None):
    """-> (Dx, Dy, offsets, pairs): the slope operators with the slope of a level node beside a
    sharp edge held at the one A shows on its own side (|grad top| = |D t + offset|), and the
    (node, neighbour over the edge) pairs.

    At a face's sharp edge the contact line pins: the face keeps its own rise up to the
    edge and the wall below has the wall's (2 mm apart for the second ink, one up and one
    down). A central difference at the face's last node reaches over the edge, reads the
    wall's slope there and puts the wall's rise on the face: the stepped block's 12 mm tier
    came out 1.2-3.6 mm high along its rims, falling off over 4 mm. A one-sided difference of
    the top is no cure: a bump at the edge, its contact line at its foot, is steep on that
    side too and solves the equation as well (the exact apparent surface of that tier: +2.3 mm
    at the edge). So where A (the fit of the contact lines as seen: fixed) is level on one
    side of a node (under level_slope over two spacings) and steeper than EDGE_SLOPE on the
    other (over one of two: the fit rounds the edge), the node's slope along that axis is A's
    on the level side: the face as the contact lines crossing it show it.

    `exposed`: the first-exposure heights the fit was given (NaN where none, and where a face
    hid the node). A thin-plate fit rings beside a 14 mm wall: the steps' boss top, level in
    its first-exposure heights to 0.02 mm, stood 0.2-0.5 mm uneven in A over its last two
    nodes, no edge was found along most of its rim, and the wall's rise carried 1-1.7 mm onto
    it. So a side counts as level where either A or the first-exposure heights are (the
    flatter of the two differences)."""
    A = fill_nearest(A)
    index = problem.index
    ops, offsets, pairs = [], [], []
    gradient = problem.gradient()
    for D, axis, h in ((gradient[0], 1, problem.lat.hx), (gradient[1], 0, problem.lat.hy)):
        back = _flatter(np.diff(A, axis=axis, prepend=np.nan), exposed, axis) / h  # A[i] - A[i - 1]
        ahead = _shifted(back, -1, axis)  # A[i + 1] - A[i]
        back2, ahead2 = _shifted(back, 1, axis), _shifted(ahead, -1, axis)
        offset = np.zeros(problem.n)
        held = np.zeros(problem.n, bool)
        step = np.zeros(2, int)
        step[axis] = 1
        for level, level2, steep, steep2, over in (
            (back, back2, ahead, ahead2, 1),
            (ahead, ahead2, back, back2, -1),
        ):
            with np.errstate(invalid="ignore"):
                edge = trusted & (np.abs(level) < level_slope) & (np.abs(level2) < level_slope)
                edge &= np.fmax(np.abs(steep), np.abs(steep2)) > EDGE_SLOPE
            J, I = np.nonzero(edge)
            me = index[J, I]
            held[me] = True
            offset[me] = level[J, I]
            kk, ll = J + over * step[0], I + over * step[1]
            inside = (kk >= 0) & (ll >= 0) & (kk < A.shape[0]) & (ll < A.shape[1])
            across = np.full(kk.size, -1)
            across[inside] = index[kk[inside], ll[inside]]
            pairs.extend((m, n) for m, n in zip(me, across) if n >= 0)
        ops.append(sp.diags((~held).astype(float)) @ D if held.any() else D)
        offsets.append(offset)
    return ops[0], ops[1], offsets, pairs


def _flatter(diff, exposed, axis):
    """Each backward difference of A, or of the first-exposure heights where they have one
    and it is smaller."""
    if exposed is None:
        return diff
    seen = np.diff(exposed, axis=axis, prepend=np.nan)
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(seen) < np.abs(diff), seen, diff)


def _shifted(a, k, axis):
    """a moved k places along axis (out[i] = a[i - k]), NaN where nothing moved in."""
    out = np.full(a.shape, np.nan)
    src = [slice(None)] * 2
    dst = [slice(None)] * 2
    src[axis] = slice(max(0, -k), a.shape[axis] - max(0, k))
    dst[axis] = slice(max(0, k), a.shape[axis] - max(0, -k))
    out[tuple(dst)] = a[tuple(src)]
    return out


def rows_not_over(rows, edges):
    """The smoothness rows but those that span an edge (touch a node and its neighbour over
    the edge): the rise jumps there, and so does the top's slope."""
    if not edges:
        return rows
    reach = abs(rows).tocsc()
    reach.data[:] = 1.0
    m, a = np.array(edges).T
    over = np.asarray((reach[:, m].multiply(reach[:, a])).max(axis=1).todense()).ravel() > 0
    return sp.diags((~over).astype(float)) @ rows


def slope_range_near_walls(lat, A, footprint, active, slope_of_a, inset):
    """-> (lo, hi) per active node: the range the solve reads the top's slope in when it works
    out the rise h(|grad top|); `slope_of_a`: A's slope by the solve's own operators; `inset`:
    how many nodes inside the outline a wall is the part's own, not its outline's (there the
    solve's rim band and its tie hold the top: contact_lines.top_from_apparent).

    top - h(|grad top|) = A has a mode along a face's slope: lift the top by d and its slope
    changes by d', its rise by h'(g) d', so d = h' d' solves it to first order and grows as
    exp(s / h') along the slope (h' = dh/d|grad|, 2.2 mm on the blade's 24 deg face under the
    first ink). Where the fit of A is rounded, at a wall's crest or foot, the mode starts:
    the blade's gentle face came out +0.45 mm 3 mm below its crest and +1.3 at it (first
    ink), the slab beyond its flank's foot +0.94 falling to +0.13 over 5 mm (second ink).
    On a plane face the top's slope is A's (the rise is the same all over it), so near a
    wall it is read within SLOPE_PLAY of A's, which holds the mode to h' times the play.
    Only near walls inside the part: held everywhere, sample 4 (its walls its outline, its
    top curved, so that its top's slope leaves A's by more) went from 0.029 to 0.079 mm."""
    inner = ndimage.binary_erosion(footprint, iterations=inset, border_value=0)
    walls = (steepness(lat, A) > EDGE_SLOPE) & inner
    near = ndimage.binary_dilation(walls, iterations=WALL_REACH)[active]
    part, plus = SLOPE_PLAY
    lo = np.where(near, np.maximum(slope_of_a * (1 - part) - plus, 0.0), 0.0)
    hi = np.where(near, slope_of_a * (1 + part) + plus, np.inf)
    return lo, hi
