"""Where the meniscus solve finds a face's sharp edge (surface/sharp_edges.py)."""

import numpy as np
from scipy import ndimage

from appliance.surface.gridfit import FitProblem
from appliance.surface.lattice import Lattice
from appliance.surface.sharp_edges import slopes_held_at_edges


def _held_columns(A, exposed):
    """The columns of the nodes held at an edge along x, on a 20 x 12 lattice (1 mm)."""
    lat = Lattice(np.arange(20.0), np.arange(12.0))
    fp = np.ones(lat.shape, bool)
    problem = FitProblem(lat, fp)
    trusted = ndimage.binary_erosion(fp, iterations=2, border_value=0)
    _, _, _, pairs = slopes_held_at_edges(problem, A, trusted, 0.15, exposed)
    J, I = np.nonzero(problem.index >= 0)
    col = dict(zip(problem.index[J, I], I))
    return sorted({int(col[m]) for m, _ in pairs})


def test_a_face_is_held_at_its_edge_by_its_first_exposure_not_by_a_hidden_strips_own():
    # a face at 10 mm (columns 0-9) whose fit rings over its last two nodes, a strip a rim hid
    # (10-11: the fit ramps there), and the wall's top at 20 mm (12-19)
    row = np.array([10.0] * 8 + [10.3, 9.7, 13.0, 17.0] + [20.0] * 8)
    A = np.tile(row, (12, 1))
    seen = np.tile(np.array([10.0] * 10 + [np.nan, np.nan] + [20.0] * 8), (12, 1))
    raw = np.tile(np.array([10.0] * 12 + [20.0] * 8), (12, 1))  # the strip came out with the base
    # held: the last two nodes of a level side beside the steep one (the wall's top: 12, 13)
    assert _held_columns(A, None) == [12, 13]  # the ringing hides the face's edge
    assert _held_columns(A, seen) == [8, 9, 12, 13]  # the face's own last nodes
    # the strip's own first exposure (the base beyond the wall's foot) moves the edge into it
    assert _held_columns(A, raw) == [10, 11, 12, 13]
