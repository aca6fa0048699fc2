"""Faces flatter than the contact angle: the ink leaves them all at once.

On a face flatter than the contact angle the contact line sits d = -h(0) below the free
surface (a puddle of this ink is d deep): a flat face at z stays under until the ink is
d above it and then comes out all at once, between two frames, with no contact line ever
crossing it. What the frames say about it is a bracket: out at L_k, under at L_(k-1), so
its apparent height A = z + d lies in (L_k, L_(k-1)]; nothing finer (the rendered second
ink's twin-peaks: A = 7.38 in (6.70, 7.91]). Before, such faces came out at the bracket's
bottom or anywhere the fit ran on to (twin-peaks' 6 mm skirt 0.62 mm low, the crater's
outer band 0.26-0.67, the steep front's apron likewise). Now:
 - in the frame that uncovered a face, its rim is a wall (pinned_rims_as_walls). The ink
   stands up to d above the rim then, pinned at the sharp edge: the waterline along the
   outline is that edge, seen up to d below the ink, not a level curve of A at L_k; nor
   does it stay put in perspective like an edge above the ink, so the wall test misses it.
   Such a stretch can show a few tenths inside the outline (the rendered second ink's
   ring: 0.4 mm inside its 45 mm edge), but no ink stands on a face flatter than the
   contact angle without a contact line crossing it: where the wall under the edge is
   upright (the frame below runs on the outline), the stretch is moved onto the edge,
   and the face came out to it;
 - nodes well inside such a face (no contact line of frame k within l_c, the meniscus'
   reach, and the one above further than its own spacing says) go to the middle of their
   bracket, never more than half a step out (place_dewetted_faces); the rest of the face's
   nodes are held in the bracket after the fit (bracket_dewetted_faces).
Within half a step is what the frames allow: a finer level step near the face, not a
cleverer fit, is what would place it closer.
"""

from __future__ import annotations

import numpy as np

from .meniscus import MeniscusModel
from .slices import polyline_distance, polyline_nearest

DEPRESSION_MIN_MM = 0.05  # shallower, a flat face comes out within that of its height


def depression_depth(model: MeniscusModel) -> float:
    """d = -h(0): how far the ink stands above a flat face it has just left; 0 for an ink
    that wets it or one whose depression is under DEPRESSION_MIN_MM (the first ink commissions
    to 0.04 deg: 0.002 mm)."""
    d = -float(model.rise(0.0))
    return d if d >= DEPRESSION_MIN_MM else 0.0


def pinned_rims_as_walls(slices, model: MeniscusModel, wall_tol_mm):
    """-> slices whose pinned rims are walls: stretches along the part's outline (the lowest
    frame's waterline) with no contact line of the frame above within l_c (the face inside
    was under ink there a frame ago and came out at once). Along the outline means within
    what a rim seen up to 3 d off its height moves in perspective (d for the pinned edge
    itself, the rest for the lowest frame's edges, put back with the fit's rim heights).
    Over an upright wall the stretch is moved onto the edge (_onto_edge).
    Only with a depression (d > 0): otherwise the slices as they are."""
    d = depression_depth(model)
    visible = [k for k, s in enumerate(slices) if not s.empty]
    if d <= 0 or len(visible) < 3:
        return slices
    lowest = slices[visible[-1]]
    out = list(slices)
    for k, below in zip(visible[1:-1], visible[2:]):
        s = slices[k]
        wall = np.zeros(len(s.P), bool) if s.wall is None else s.wall
        if wall.all():
            continue
        tol = np.full(len(s.P), wall_tol_mm + 0.02)
        if model.camera_xy_mm is not None and model.camera_height_mm:
            r = np.hypot(*(s.P - np.asarray(model.camera_xy_mm, float)).T)
            tol += 3.0 * d * r / model.camera_height_mm
        pinned = ~wall & (polyline_distance(lowest, s.P)[0] < tol)
        if pinned.any():
            # ... and only where the face inside came out at once: no contact line above
            # within the meniscus' reach
            i = np.flatnonzero(pinned)
            pinned[i] = _distance_to_contact_line(slices, k - 1, s.P[i]) > model.capillary_length_mm
        if not pinned.any():
            continue
        t = s.moved(_onto_edge(s.P, pinned, slices[below], lowest, wall_tol_mm), s.z)
        t.wall = wall | pinned
        out[k] = t
    return out


def _onto_edge(P, pinned, below, lowest, wall_tol_mm):
    """P with the pinned points seen inside an edge moved onto it: the ink is held at the
    edge, not inside it (seen 0.4 mm inside, the ring's outermost nodes came out a frame late
    and stood 1.6 mm low). Only where the frame below runs on the outline there (a vertical
    wall under the edge): beside a wall that leans in, the outline is not the edge."""
    edge = polyline_nearest(below, P[pinned])
    upright = polyline_distance(lowest, edge)[0] < wall_tol_mm + 0.02
    if not upright.any():
        return P
    out = P.copy()
    out[np.flatnonzero(pinned)[upright]] = edge[upright]
    return out


def _distance_to_contact_line(slices, k, q):
    top = next(j for j, s in enumerate(slices) if not s.empty)
    return polyline_distance(slices[k].level_curve(), q)[0] if k >= top else np.full(len(q), np.inf)


FACE_SPACINGS = 2  # a face: its contact line above is this many of their spacings away


def _dewetted(lat, z_fe, first, footprint, slices, model):
    """-> [(frame k, node indices, deep)] for the nodes no contact line placed (no first-exposure
    height) and none of the frame k that uncovered them passes within the meniscus' reach
    (l_c); `deep`: also further from frame k - 1's contact line than FACE_SPACINGS times the
    spacing from there to frame k - 2's, plus 2 l_c): well inside a face, not at the bottom of
    a bowl, which the fit continues the contact lines above into (a paraboloid: 0.01 mm)."""
    K = len(slices)
    top = next(k for k, s in enumerate(slices) if not s.empty)
    todo = footprint & ~np.isfinite(z_fe) & (first > top) & (first < K)
    out = []
    if depression_depth(model) <= 0 or not todo.any():
        return out
    X, Y = np.meshgrid(lat.x, lat.y)
    reach = model.capillary_length_mm
    for k in np.unique(first[todo]):
        sel = todo & (first == k)
        q = np.column_stack([X[sel], Y[sel]])
        far = _distance_to_contact_line(slices, k, q) > reach
        d_up = _distance_to_contact_line(slices, k - 1, q[far])
        d_up2 = _distance_to_contact_line(slices, k - 2, q[far])
        with np.errstate(invalid="ignore"):
            spacing = np.where(np.isfinite(d_up2), np.abs(d_up2 - d_up), d_up)
        out.append((int(k), np.flatnonzero(sel.ravel())[far], d_up > FACE_SPACINGS * spacing + 2 * reach))
    return out


def dewetted_nodes(lat, z_fe, first, footprint, slices, model: MeniscusModel):
    """-> mask of the nodes of faces that came out at once (those place_dewetted_faces and
    bracket_dewetted_faces hold in their brackets), or None when there are none."""
    found = _dewetted(lat, z_fe, first, footprint, slices, model)
    if not found:
        return None
    mask = np.zeros(lat.shape, bool)
    for _, idx, _ in found:
        mask.ravel()[idx] = True
    return mask


def place_dewetted_faces(lat, z_fe, first, footprint, slices, model: MeniscusModel):
    """First-exposure heights for the nodes well inside faces that came out all at once: the
    middle of their bracket (L_k, L_(k-1)], never more than half a step out. Only with a
    depression."""
    out = z_fe
    for k, idx, deep in _dewetted(lat, z_fe, first, footprint, slices, model):
        if deep.any():
            out = out.copy() if out is z_fe else out
            out.ravel()[idx[deep]] = 0.5 * (slices[k].level + slices[k - 1].level)
    return out


def bracket_dewetted_faces(lat, apparent, z_fe, first, footprint, slices, model: MeniscusModel):
    """The fitted apparent surface with the rest of those nodes (at a face's edge) held in
    their bracket: the fit continues the contact lines above into them, which on a skirt
    flattening into a face runs on past the level that still covered it (an ideal twin-peaks:
    0.5-1.3 mm high). Only with a depression."""
    out = apparent
    for k, idx, _ in _dewetted(lat, z_fe, first, footprint, slices, model):
        out = out.copy() if out is apparent else out
        out.ravel()[idx] = np.clip(out.ravel()[idx], slices[k].level, slices[k - 1].level)
    return out
