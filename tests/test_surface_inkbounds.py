"""The floor and ceiling the frames give each node (surface/inkbounds.py), where they clash."""

import numpy as np

from appliance.surface.inkbounds import NodeBounds, _without_clashes


def test_a_node_out_of_the_ink_above_where_ink_was_seen_over_it_keeps_neither_bound():
    # node 0: consistent (out at 5, ink at 8); node 1: out at 35 but ink seen at 17.5 (a
    # waterline's noise at a wall's edge: harsh sample 4 stood 21 mm low held to it)
    b = NodeBounds(np.array([True, True]), np.array([5.0, 35.0]), np.array([8.0, 17.5]))
    out = _without_clashes(b)
    assert out.floor[0] == 5.0 and out.ceiling[0] == 8.0 and out.hidden[0]
    assert out.floor[1] == -np.inf and out.ceiling[1] == np.inf and not out.hidden[1]
