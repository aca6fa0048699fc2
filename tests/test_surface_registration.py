"""Frames registered on the walls they share (surface/registration.py).

A 20 mm block whose top is a plane rising from 10 mm at x = 0 to 20 mm at x = 20: at a level
between the two its waterline runs along three walls (x = 20, y = 0, y = 20), which stay put
from frame to frame, and across the top at x = 2 (L - 10), which moves 2 mm a level. A stage
that plays sideways shifts each frame's whole waterline; the walls tell by how much.
"""

import numpy as np

from appliance.surface.registration import pair_shifts, registered, slice_key
from appliance.surface.slices import make_slice

LEVELS = np.arange(19.7, 10.0, -0.3)


def _rectangle(x0, x1, y0, y1, step=0.1):
    def edge(a, b):
        n = max(int(np.hypot(*(b - a)) / step), 1)
        return a + (b - a) * (np.arange(n) / n)[:, None]

    c = [np.array(p, float) for p in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
    return np.vstack([edge(c[i], c[(i + 1) % 4]) for i in range(4)])  # counter-clockwise


def _frames(play):
    """The block's slices, each frame's waterline shifted by its row of `play` (mm)."""
    return [
        make_slice(L, [_rectangle(2.0 * (L - 10.0), 20.0, 0.0, 20.0) + off]) for L, off in zip(LEVELS, play)
    ]


def test_each_frames_stage_play_is_measured_on_the_walls_and_taken_out():
    rng = np.random.default_rng(3)
    r, a = 0.05 * np.sqrt(rng.uniform(size=LEVELS.size)), rng.uniform(0, 2 * np.pi, LEVELS.size)
    play = np.column_stack([r * np.cos(a), r * np.sin(a)])
    frames = _frames(play)
    out, offsets = registered(frames)

    def walls(slices):
        """Per frame: where its wall x = 20 and its wall y = 0 stand."""
        at = []
        for s in slices:
            side = (s.P[:, 0] > 19.8) & (np.abs(s.P[:, 1] - 10.0) < 9.5)
            foot = (s.P[:, 1] < 0.2) & (s.P[:, 0] < 19.8) & (s.P[:, 0] > s.P[:, 0].min() + 0.2)
            at.append((s.P[side, 0].mean(), s.P[foot, 1].mean()))
        return np.array(at)

    before, after = walls(frames), walls(out)
    assert np.ptp(before, axis=0).min() > 0.05  # the play moved the walls by up to 0.1 mm
    # moved back, the frames' walls line up (what stays is the play's slow part, registration._trend),
    # where the frames share long walls in both directions (the lower half: y walls over 10 mm)
    low = LEVELS < 15.0
    assert np.all(after[low].std(axis=0) < 0.4 * before[low].std(axis=0))
    assert np.abs(offsets[:, 0] - (before[:, 0] - after[:, 0])).max() < 1e-9  # the offsets say by how much


def test_frames_without_play_come_back_as_they_were():
    frames = _frames(np.zeros((LEVELS.size, 2)))
    out, offsets = registered(frames)
    assert all(a is b for a, b in zip(out, frames))
    assert np.abs(offsets).max() < 0.005


def test_a_steep_face_moving_outwards_is_not_taken_for_play():
    """A cap steeper and steeper towards its wall (the demo sphere above its rim) widens its
    waterline by a few hundredths a level: an arc of each circle agrees on some shift that no
    stage made. Two levels apart the arc and the shift are others, so no triangle closes and
    nothing moves (before the closure, the sphere's frames moved by up to 0.17 mm)."""
    t = np.linspace(0, 2 * np.pi, 1200, endpoint=False)
    circle = np.column_stack([np.cos(t), np.sin(t)])
    growth = np.cumsum(np.linspace(0.02, 0.11, LEVELS.size))  # outwards, faster as it steepens
    frames = [make_slice(L, [50 + (20 + g) * circle]) for L, g in zip(LEVELS, growth)]
    out, offsets = registered(frames)
    assert all(a is b for a, b in zip(out, frames)), np.abs(offsets).max()


def test_walls_seen_on_one_side_only_that_lean_out_are_not_taken_for_play():
    """The block's front (x = 20) leans out by 0.05 mm a frame down to mid-height, then its
    back (y = 20) does below: as on physics2's steep front, the wall a pair sees across
    changes half way, each move alone is the same as a shift across that wall, and the
    offsets' slow trend cannot absorb the bend. The steps are alike from frame to frame, not
    anti-correlated as play makes them, so without any play no frame moves (before the gate
    frames moved by up to 0.10 mm here, 0.08 mm on the steep front in benches/meniscus.py)."""
    k = np.arange(LEVELS.size)
    front, back = 0.05 * np.minimum(k, LEVELS.size // 2), 0.05 * np.maximum(0, k - LEVELS.size // 2)
    frames = [
        make_slice(L, [_rectangle(2.0 * (L - 10.0), 20.0 + a, 0.0, 20.0 + b)])
        for L, a, b in zip(LEVELS, front, back)
    ]
    out, offsets = registered(frames)
    assert all(a is b for a, b in zip(out, frames))
    assert not offsets.any()


def _with_post(play):
    """The block's frames with a square post beside it (walls facing -x and +x that stay put):
    across x the frames now share walls facing each other."""
    return [
        make_slice(L, [_rectangle(2.0 * (L - 10.0), 20.0, 0.0, 20.0) + off, _rectangle(-10, -5, 5, 15) + off])
        for L, off in zip(LEVELS, play)
    ]


def test_frames_shifted_by_the_stages_play_are_moved_back_across_walls_facing_each_other():
    """Every third frame 0.05 mm off in x (the harsh bench's play; enough frames that their
    offsets' rms passes NOTHING_TO_DO_MM): the post's walls and the block's far wall tell it,
    and those frames are moved back in line with the others."""
    play = np.zeros((LEVELS.size, 2))
    play[::3, 0] = 0.05
    frames = _with_post(play)
    out, offsets = registered(frames)

    def post_x(slices):
        return np.array([s.P[s.P[:, 0] < -4.0, 0].mean() for s in slices])

    assert np.ptp(post_x(frames)) > 0.049
    assert np.ptp(post_x(out)[3:-3]) < 0.01  # in line, to a fifth of the play
    assert np.ptp(post_x(out)) < 0.025  # the ends too, less well (one-sided pairs and trend)
    assert np.abs(offsets[:, 1]).max() < 0.005  # and nothing made up across y


def test_pairs_measured_while_the_scan_ran_are_used_and_the_rest_measured():
    rng = np.random.default_rng(5)
    frames = _frames(rng.uniform(-0.04, 0.04, (LEVELS.size, 2)))
    whole = pair_shifts(frames)
    memo = {}
    early = pair_shifts(frames[:10], memo=memo)  # the frames read before the scan ended
    assert len(memo) == len(early)
    at_end = pair_shifts(frames, memo=memo)
    assert at_end.keys() == whole.keys() and len(memo) == len(whole)
    assert all(np.array_equal(at_end[k][0], whole[k][0]) for k in whole)
    # a pair in the memo is taken from it, not measured again
    key = (slice_key(frames[0]), slice_key(frames[1]))
    memo[key] = (np.array([9.0, 9.0]), np.eye(2))
    assert np.array_equal(pair_shifts(frames, memo=memo)[(0, 1)][0], [9.0, 9.0])
    # a frame with other points is another slice: its pairs are measured
    moved = [frames[0].moved(frames[0].P + 0.01, frames[0].z), *frames[1:]]
    assert not np.array_equal(pair_shifts(moved, memo=memo)[(0, 1)][0], [9.0, 9.0])
