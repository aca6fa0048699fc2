"""The ray over a hidden wall's rim bounds what stands behind it.

The camera at (0, 0), 300 mm over the ink, sees a block's far rim (x = 60, 20 mm high)
over the ink at level 10 mm: 60 * 300 / 290 = 62.07 mm out. The line from the camera
over the rim is empty down to that ink, so a point behind the rim stands under it."""

import numpy as np
from test_surface_occlusion import CAMERA, LEVELS, RIM_MM, RUN, _frustum_seen_and_corrected

from appliance.surface.inkbounds import node_bounds
from appliance.surface.perspective import Perspective
from appliance.surface.rimrays import SEEN_TOL_MM, under_rim_rays
from appliance.surface.slices import make_slice

FOOT = Perspective((0.0, 0.0), 300.0)
RIM_X, RIM_Z = 60.0, 20.0


def _landing(level):
    """Where the ray over the rim meets the ink at `level`."""
    return RIM_X * FOOT.height_mm / (FOOT.height_mm - (RIM_Z - level))


def _ray_over_rim(x, level):
    """The exact ray's height at x (y = 0), from the camera over the rim."""
    return RIM_Z - (x - RIM_X) * (FOOT.height_mm - (RIM_Z - level)) / RIM_X


def _block_seen(level, far_x, slant=0.0):
    """A frame of the block: its outline as the camera saw it, the far side at far_x (plus
    slant * y), and the same with that side's rim put back at x = 60, marked as an edge."""
    side = np.linspace(-10.0, 10.0, 201)
    far = np.column_stack([far_x + slant * side, side])
    near = np.column_stack([np.full(201, 40.0), side[::-1]])
    loop = np.vstack([far, near])
    seen = make_slice(level, [loop])
    put_back = make_slice(level, [np.vstack([np.column_stack([np.full(201, RIM_X), side]), near])])
    put_back.edge = np.r_[np.ones(201, bool), np.zeros(201, bool)]
    return seen, put_back


def test_a_point_behind_the_rim_stands_under_the_ray_over_it():
    seen, put_back = _block_seen(10.0, _landing(10.0))
    q = np.array([[61.0, 0.0], [60.5, 3.0], [45.0, 0.0]])
    ceiling = under_rim_rays(q, [seen], [put_back], FOOT, 3.4)
    exact = _ray_over_rim(q[:2, 0], 10.0)
    # the ray, raised by a pixel's worth where it lands
    assert np.all(ceiling[:2] >= exact) and np.all(ceiling[:2] < exact + 0.35)
    # a point whose nearest waterline is not a rim put back: nothing said
    assert ceiling[2] == np.inf
    # nor by a camera whose pose is unknown
    assert np.all(under_rim_rays(q, [seen], [put_back], None, 3.4) == np.inf)


def test_the_ray_is_the_one_from_the_camera_s_foot_through_the_point():
    """A rim seen slanting across the line from the camera: the nearest point of the
    waterline is 0.89 mm from (61, 0), but the ray over (61, 0) meets the ink 1 mm out, on
    the line from the foot. Taking the nearest distance would put the ceiling 0.5 mm low."""
    seen, put_back = _block_seen(10.0, 62.0, slant=0.5)
    ceiling = under_rim_rays(np.array([[61.0, 0.0]]), [seen], [put_back], FOOT, 3.4)[0]
    t = 1.0 + SEEN_TOL_MM
    assert abs(ceiling - (10.0 + FOOT.height_mm * t / (61.0 + t))) < 0.02


def test_of_the_frames_rays_the_highest_counts():
    """Every frame below the rim sees the same ray land further out. Where it lands on ink
    that climbed the hidden wall it meets the ink early, and read on the flat ink it passes
    low: the frame whose ink lay flat says where the ray is."""
    flat = _block_seen(10.0, _landing(10.0))
    climbed = _block_seen(8.0, _landing(8.0) - 0.15)  # met the ink 0.15 mm early
    q = np.array([[61.0, 0.0]])
    both = under_rim_rays(q, [flat[0], climbed[0]], [flat[1], climbed[1]], FOOT, 3.4)
    alone = under_rim_rays(q, [climbed[0]], [climbed[1]], FOOT, 3.4)
    assert alone[0] < _ray_over_rim(61.0, 10.0) - 0.4
    assert both[0] >= _ray_over_rim(61.0, 10.0)


def test_a_node_the_frames_hid_stands_under_the_ray_over_its_rim():
    """Behind the frustum's far rim, just past it, no frame saw ink over a node (the top
    frame's silhouette landed beyond it): the frames' levels gave it no ceiling at all, and
    elsewhere behind the rim one as high as the ink might have climbed (2 mm here). The ray
    over the rim holds such a node, above the true part, and lowers no other ceiling."""
    seen, corrected, lat = _frustum_seen_and_corrected()
    X, Y = np.meshgrid(lat.x, lat.y)
    outside = np.maximum(np.maximum(np.abs(X - 50) - 10, np.abs(Y) - 10), 0.0)
    truth = RIM_MM - outside / RUN
    never = np.full(lat.shape, len(seen))
    everywhere = np.ones(lat.shape, bool)
    climb = node_bounds(lat, seen, corrected, never, everywhere, rise_max=2.0)
    rays = node_bounds(lat, seen, corrected, never, everywhere, rise_max=2.0, camera=CAMERA)
    behind = (X > 60) & (np.abs(Y) < 8) & (truth > LEVELS[-1])
    lowered = behind & (rays.ceiling < climb.ceiling - 0.5)
    assert lowered.sum() > 20
    assert np.all(rays.ceiling[lowered] >= truth[lowered])
    assert np.all(rays.ceiling[lowered] < truth[lowered] + 3.0)
    assert rays.ray[lowered].all()
    # nowhere higher, and nothing said in front of the wall that faces the camera
    assert np.all(rays.ceiling <= climb.ceiling)
    assert np.array_equal(rays.ceiling[X < 38], climb.ceiling[X < 38])
