"""Pockets that held ink (surface/pools.py): a hole whose far shore recedes as the ink drops is
a pool the pocket kept, its floor unseen; the map holds it no lower than its ink can have
stood, so the program cuts none of it, and the report and the G-code header say so. A hole
the tank's ink reaches (a wall's foot, a funnel's slope) is no pool."""

from dataclasses import replace

import numpy as np

from appliance.cli import main
from appliance.outputs import read_heightmap_csv
from appliance.sim.render import PRESETS
from appliance.sim.scanrender import render_scan
from appliance.sim.surfaces import Surface, Tier, disc_sdf
from appliance.surface.heightmap import HeightMap
from appliance.surface.perspective import Perspective
from appliance.surface.pools import cover_held_pools, held_pools, pools_suspected
from appliance.surface.uncertainty import HELD, SOURCES
from appliance.vision.types import signed_area

CAMERA = Perspective((0.0, 0.0), 300.0)  # its foot well off the part: shores recede outwards
CENTRE = np.array([50.0, 50.0])


def _circle(r, clockwise, n=400):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False) * (-1 if clockwise else 1)
    return CENTRE + r * np.column_stack([np.cos(t), np.sin(t)])


def _seen(loop, height_above_ink):
    """A loop standing h above the ink, where the camera sees it."""
    C = np.asarray(CAMERA.xy)
    return C + (loop - C) * CAMERA.height_mm / (CAMERA.height_mm - height_above_ink)


def _frames(hole_at, top=21.0, bottom=2.0):
    """(level, loops) top first: an empty frame above `top`, then a disc of radius 40 with
    the hole hole_at(level) -> (radius, height of its shore above the ink)."""
    frames = [(top + 1.0, [])]
    for level in np.arange(top, bottom - 0.5, -1.0):
        r, h = hole_at(level)
        frames.append((float(level), [_circle(40, False), _seen(_circle(r, True), h)]))
    return frames


def _pool_frames():
    """A pool 15 mm across, its surface at 20.5 mm: the 21 mm frame saw its pocket open."""
    frames = _frames(lambda L: (15.0, 20.5 - L))
    frames[1] = (21.0, [_circle(40, False)])
    return frames


def test_a_hole_whose_shore_stands_above_the_ink_is_a_held_pool():
    frames = _pool_frames()
    (pool,) = held_pools(frames, CAMERA)
    assert pool.bracket == (20.0, 21.0)
    r = np.hypot(*(pool.shore - CENTRE).T)
    assert abs(r.mean() - 15.0) < 0.2  # put back from where the lowest frame saw it
    assert pools_suspected(frames, CAMERA)  # a hole growing as the ink drops


def test_a_crescent_shaped_pool_is_found_too():
    """Its vertices' mean lies outside it: the point it is followed by must not."""
    t = np.linspace(0.0, 2 * np.pi, 400, endpoint=False)
    outer = np.column_stack([np.cos(t), np.sin(t)]) * 15.0
    inner = np.column_stack([np.cos(t), np.sin(t)]) * 11.0 + [6.0, 0.0]  # bitten out of it
    crescent = np.array([p for p in outer if np.hypot(*(p - [6.0, 0.0])) > 11.0])
    bite = np.array([p for p in inner if np.hypot(*p) < 15.0])[::-1]
    loop = CENTRE + np.vstack([crescent, bite])
    loop = loop if signed_area(loop) < 0 else loop[::-1]  # a hole: clockwise
    frames = [(22.0, [])] + [
        (float(L), [_circle(40, False), _seen(loop, 20.5 - L)]) for L in np.arange(20.0, 1.5, -1.0)
    ]
    (pool,) = held_pools(frames, CAMERA)
    assert pool.bracket == (20.0, 22.0)


def test_holes_the_tanks_ink_reaches_are_no_pools():
    wall = _frames(lambda L: (15.0, 0.0))  # a wall's foot: stays put
    funnel = _frames(lambda L: (5.0 + 0.5 * L, 0.0))  # a slope: closes in as the ink drops
    assert held_pools(wall, CAMERA) == [] and held_pools(funnel, CAMERA) == []
    assert not pools_suspected(wall, CAMERA) and not pools_suspected(funnel, CAMERA)
    assert held_pools(_frames(lambda L: (15.0, 20.5 - L)), None) == []  # no camera: no telling


def test_a_pool_a_read_lost_above_the_lowest_frames_is_suspected():
    # a read that confirms part by the lower frames alone cuts a receding shore away:
    # the hole is gone a frame above the lowest, where the part still shows
    frames = _frames(lambda L: (15.0, 20.5 - L))
    frames[-2] = (frames[-2][0], [_circle(40, False)])
    assert pools_suspected(frames, CAMERA)


def test_a_held_pool_is_covered_at_the_highest_its_ink_can_have_stood():
    x = y = np.arange(30.0, 70.01, 0.5)
    X, Y = np.meshgrid(x, y)
    inside = np.hypot(X - 50, Y - 50) < 15
    hm = HeightMap(x, y, np.where(inside, np.nan, 20.0), np.full(X.shape, 0.01), np.zeros(X.shape, np.int8))
    (pool,) = held_pools(_pool_frames(), CAMERA)
    covered, notes = cover_held_pools(hm, [pool], rise_mm=1.5)
    assert np.all(covered.z[inside] == 21.0 + 1.5)  # the bracket's top, 21, and the meniscus' cling
    assert np.all(covered.source[inside] == HELD) and SOURCES[HELD] == "held"
    assert np.all(covered.sigma[inside] > 1.0)
    beyond = np.hypot(X - 50, Y - 50) > 15.5  # the shore is put back to within a cell
    assert np.array_equal(covered.z[beyond], hm.z[beyond])
    assert len(notes) == 1 and "x 50.0, y 50.0" in notes[0] and "22.50 mm" in notes[0]


def test_what_stands_out_of_a_pool_keeps_its_own_heights():
    # a boss in the pool: where the pool meets it stands as high above the ink as the shore
    frames = [
        (level, loops + [_seen(_circle(4, False), 20.5 - level)] if len(loops) > 1 else loops)
        for level, loops in _pool_frames()
    ]
    (pool,) = held_pools(frames, CAMERA)
    assert len(pool.islands) == 1
    x = y = np.arange(30.0, 70.01, 0.5)
    X, Y = np.meshgrid(x, y)
    hm = HeightMap(x, y, np.full(X.shape, 30.0))  # a boss 30 mm high in the middle of the pool
    covered, _ = cover_held_pools(hm, [pool])
    r = np.hypot(X - 50, Y - 50)
    assert np.all(covered.z[r < 3.5] == 30.0) and np.all(covered.z[(r > 4.5) & (r < 14)] == 21.0)


BOWL = Surface(
    "bowl",
    "a bowl 30 mm across, its rim at 16 mm and its floor at 10",
    (35.0, 65.0, 35.0, 65.0),
    (Tier(disc_sdf(50, 50, 15), lambda x, y: 10 + 6 * ((x - 50) ** 2 + (y - 50) ** 2) / 225.0),),
)


def _bowl_scan(tmp_path, held):
    scan = tmp_path / ("held" if held else "drained")
    effects = replace(PRESETS["clean"], trapped_ink=held)
    render_scan(BOWL, scan, levels=[float(v) for v in range(17, 0, -1)], effects=effects, seed=1)
    (tmp_path / f"{scan.name}.truth.json").unlink()  # a test part: no statistics against it
    out = tmp_path / f"{scan.name}-out"
    assert main(["process", str(scan), "-o", str(out)]) == 0
    hm = read_heightmap_csv(out / "heightmap.csv")
    X, Y = hm.grid()
    return out, hm, hm.z - BOWL.height(X, Y)


def test_a_bowl_that_held_its_ink_gets_a_program_that_leaves_it_uncut(tmp_path):
    out, hm, err = _bowl_scan(tmp_path, held=True)
    held = hm.source == HELD
    assert held.sum() > 0.8 * np.pi * 14**2 / (hm.spacing[0] * hm.spacing[1])  # the pool's cells
    assert np.all(err[held] >= 0.0)  # nothing under the pool is cut
    assert np.allclose(hm.z[held], 16.0, atol=0.01)  # the 16 mm frame showed it open
    assert "a pocket held ink" in (out / "report.md").read_text()
    gcode = (out / "toolpath.gcode").read_text()
    assert "(pocket that held ink: X " in gcode and "left uncut at Z16.00" in gcode


def test_the_same_bowl_drained_is_scanned_as_it_is(tmp_path):
    out, hm, err = _bowl_scan(tmp_path, held=False)
    X, Y = hm.grid()
    assert not (hm.source == HELD).any()
    assert np.nanmax(np.abs(err[np.hypot(X - 50, Y - 50) < 13])) < 0.05
    assert "held ink" not in (out / "report.md").read_text()


def test_the_vision_keeps_a_receding_shore_only_when_asked():
    """Confirming part by the lower frames cuts the pool's far shore (it recedes as the part
    rises: the pool's hole is read smaller); with raised_shores the lower frames, put back
    as raised edges would have shown, confirm it."""
    from appliance.sim.render import render_frame
    from appliance.sim.rig import Rig
    from appliance.vision.pipeline import WaterlineExtractor
    from appliance.vision.types import signed_area

    effects = replace(PRESETS["clean"], trapped_ink=True, lens_distortion=False)
    frames = [(L, render_frame(BOWL, L, effects=effects)) for L in (8.0, 6.0, 4.0)]
    camera = Rig().camera_model(distorted=False)

    def hole_area(**options):
        ex = WaterlineExtractor(camera, **options)
        wl = ex.extract(frames[0][1], frames[0][0], below=frames[1:])
        return max((-signed_area(loop) for loop in wl.loops), default=0.0)

    pool = np.pi * 14.8**2 * (300 / (300 - 7.9)) ** 2  # its shore at r 14.8, 7.9 mm above the ink
    kept, cut = hole_area(raised_shores=True), hole_area()
    assert abs(kept - pool) < 0.05 * pool
    assert cut < kept - 5.0


def test_a_suspect_scan_is_read_again_and_that_read_kept_only_when_it_shows_a_pool(monkeypatch):
    """waterlines.with_held_pools: the read keeping raised shores replaces the first one only
    for a held pool (the harsh ring's wetted wall makes such shores too, read worse)."""
    from types import SimpleNamespace

    from appliance import waterlines as W
    from appliance.vision.types import Waterline

    def as_read(frames):
        return [Waterline(level, loops) for level, loops in frames]

    lost = _pool_frames()
    lost[-2] = (lost[-2][0], [_circle(40, False)])  # the first read lost the hole above the lowest
    camera = SimpleNamespace(height_mm=CAMERA.height_mm, K=np.eye(3), centre_xy=lambda: CAMERA.xy)
    scan = SimpleNamespace(camera=camera, frames=[])
    reads, second = [], {}

    class Reader:  # the second read, as TopDownReader would give it
        def __init__(self, scan, raised_shores=False):
            reads.append(raised_shores)

        def read(self, frames, final=False):
            return as_read(second["frames"])

    monkeypatch.setattr(W, "TopDownReader", Reader)
    for frames, kept in ((_pool_frames(), "again"), (_frames(lambda L: (15.0, 0.0)), "first")):
        reads.clear()
        second["frames"] = frames
        first = as_read(lost)
        out = W.with_held_pools(scan, first)
        assert reads == [True]  # read again, keeping raised shores
        assert (out is first) == (kept == "first")
    reads.clear()
    wall = as_read(_frames(lambda L: (15.0, 0.0)))
    assert W.with_held_pools(scan, wall) is wall and not reads  # nothing suspect: no second read
