"""Frames registered on the walls they share: lateral stage play taken out of the waterlines.

A stage that plays sideways puts the part up to a few hundredths of a millimetre off where
it says, differently in every frame, and no calibration knows by how much. On a face rising
at 10 that moves a level curve's height by ten times as much. What does not move between two
frames, if the stage does not, is a wall: seen by its foot it stays put; seen by its raised
top edge (a wall facing away from the camera) it moves outwards by its distance from the
camera's foot times the level step over the camera's height, which is known. Every other
point of a waterline moves outwards as the ink drops, by step / slope, each by its own.

So between two frames the wall points all show one and the same shift (the difference of
the two frames' offsets) along their normals, and the rest scatter: a vote over candidate
shifts finds it (each point voting as a foot and as a raised edge; of two equal answers the
smaller), a least-squares step refines it on the points that agree. The frames' offsets then
come from all the neighbouring pairs at once, with the stage's play as a prior (a pair that
shares one straight wall tells the shift across it only), and each frame is moved back by
its own. Below NOTHING_TO_DO_MM the offsets are the waterlines' noise and nothing is moved.

Nor is anything moved unless the shifts look like play (_plays). A wall seen on one side
only (a steep front leaning a degree, an apron's pinned rim) moves out as the ink drops just
as a shift across it would, and no statistic of its points tells the two apart; counted as
play it moved frames 0.08 mm on renders that had none (benches/meniscus.py, physics2). What
does tell them apart is the sequence: play is new in every frame, so one step's shift and
the next's are anti-correlated (-0.5 for play alone), while a wall's own move is alike from
step to step (+1).
Pure: observed slices in, slices out; reconstruct does it before anything else.
"""

from __future__ import annotations

import hashlib

import cv2
import numpy as np

from .slices import Slice, polyline_distance

PLAY_MM = 0.05  # the stage play to expect: the prior spread of each frame's offset (radius)
SEARCH_MM = 0.12  # largest shift between two frames looked for (two plays and noise)
SEARCH_STEP_MM = 0.004
AGREE_MM = 0.012  # a point agrees with a shift to within this (the waterline's noise)
PAIR_SIGMA_MM = 0.006  # how well two frames' shift is known at best
MIN_AGREEING = 30  # points that must agree before a pair's shift counts
VOTERS = 400  # points (evenly along the waterline) that vote on the shift
PAIRS = (1, 2)  # each frame is compared with the ones this many frames above it
CLOSURE_CHI2 = 9.0  # three pairs' shifts around a triangle close to within 3 x their spread
TREND_FRAMES = 9  # frames over which a drift of the offsets is their slow part, not play
STEPS_ALIKE = 0.0  # consecutive shifts less alike than this are play (_plays)
NOTHING_TO_DO_MM = 0.015  # offsets whose rms is below this are the waterlines' noise (a harsh
# sample 4 without play: 0.008 mm; with 0.05 mm of play: 0.03): the frames stay as they were


def _outward(s: Slice) -> np.ndarray:
    """Per point of the slice: +1 where the right of its loop's direction of travel is
    outside the part, -1 where it is inside (a loop's orientation, and whether it is a hole:
    inside an odd number of the others)."""
    sign = []
    for k, lp in enumerate(s.loops):
        area = 0.5 * float(np.dot(lp[:, 0], np.roll(lp[:, 1], -1)) - np.dot(lp[:, 1], np.roll(lp[:, 0], -1)))
        q = (float(lp[0, 0]), float(lp[0, 1]))
        holes = sum(
            cv2.pointPolygonTest(other.astype(np.float32).reshape(-1, 1, 2), q, False) > 0
            for j, other in enumerate(s.loops)
            if j != k
        )
        sign.append(np.full(len(lp), (1.0 if area > 0 else -1.0) * (-1.0) ** holes))
    return np.concatenate(sign) if sign else np.zeros(0)


def _candidates(upper: Slice, lower: Slice, camera_xy, camera_height_mm):
    """-> (outward normals, offsets along them, the move along them the perspective gives
    a raised wall edge there) of the lower frame's points near the upper frame's waterline."""
    d, i = polyline_distance(upper, lower.P)
    reach = np.full(len(d), SEARCH_MM + AGREE_MM)
    if camera_xy is not None and camera_height_mm:  # and as far as a raised edge moves
        r = np.hypot(*(lower.P - np.asarray(camera_xy, float)).T)
        reach += r * abs(upper.level - lower.level) / camera_height_mm
    near = d <= reach
    P, i = lower.P[near], i[near]
    if len(P) == 0:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    t = upper.P[upper.nxt[i]] - upper.P[upper.prv[i]]
    n = np.column_stack([t[:, 1], -t[:, 0]])
    length = np.hypot(*n.T)
    ok = length > 1e-9
    n, P, i = n[ok] / length[ok, None], P[ok], i[ok]
    n = n * _outward(upper)[i, None]
    foot = upper.P[i]
    s = np.einsum("ij,ij->i", n, P - foot)
    move = np.zeros(len(s))
    if camera_xy is not None and camera_height_mm:
        move = np.einsum("ij,ij->i", n, P - np.asarray(camera_xy, float))
        move *= (upper.level - lower.level) / camera_height_mm
    return n, s, move


def _distance(s, nv):
    """|s - nv| in units of AGREE_MM, (points, candidate shifts), computed in place."""
    d = s[:, None] - nv
    d /= AGREE_MM
    return np.abs(d, out=d)


def _votes(n, s, move, D, block=64):
    """Per candidate shift (rows of D), the points' votes summed: each point votes as a foot
    or as a raised edge, whichever agrees better (the larger of the two Gaussians is the one
    of the smaller distance: one exp, not two). In blocks of points: all at once, the
    (points, candidates) arrays were 50 MB a pair, the processing child's peak."""
    total = np.zeros(len(D))
    for a in range(0, len(s), block):
        nv = n[a : a + block] @ D.T
        votes = _distance(s[a : a + block], nv)
        np.minimum(votes, _distance((s - move)[a : a + block], nv), out=votes)
        votes *= votes
        votes *= -0.5
        np.exp(votes, out=votes)
        total += votes.sum(axis=0)
    return total


def pair_shift(upper: Slice, lower: Slice, camera_xy=None, camera_height_mm=None):
    """-> (shift of `lower` against `upper` in mm, 2x2 information matrix) from the points
    that agree on one shift along their normals; (zeros, zeros) when too few agree.

    A wall point is either seen by its foot (static) or by its raised edge (moved by the
    perspective, `move`): each point votes for both, and takes the one nearer the shift."""
    n, s, move = _candidates(upper, lower, camera_xy, camera_height_mm)
    none = (np.zeros(2), np.zeros((2, 2)))
    if len(s) < MIN_AGREEING:
        return none
    grid = np.arange(-SEARCH_MM, SEARCH_MM + 1e-9, SEARCH_STEP_MM)
    GX, GY = np.meshgrid(grid, grid)
    D = np.column_stack([GX.ravel(), GY.ravel()])
    every = max(1, len(s) // VOTERS)
    # of two shifts the points agree on as well (a wall that is static one way, its raised
    # edge the other), the smaller: the stage plays by PLAY_MM
    total = _votes(n[::every], s[::every], move[::every], D)
    shift = D[int(np.argmax(total * np.exp(-0.5 * np.sum(D**2, axis=1) / PLAY_MM**2)))]
    for _ in range(3):  # least squares on the points that agree
        static, raised = s - n @ shift, s - move - n @ shift
        value = np.where(np.abs(static) <= np.abs(raised), s, s - move)
        agree = np.minimum(np.abs(static), np.abs(raised)) < 2 * AGREE_MM
        if agree.sum() < MIN_AGREEING:
            return none
        # (points along one straight wall tell the shift across it only: along it the
        # solve keeps it near zero and the information matrix says it is unknown)
        info = n[agree].T @ n[agree]
        shift = np.linalg.solve(info + np.eye(2), n[agree].T @ value[agree])
    # a pair's shift is known to PAIR_SIGMA_MM where its points cover every direction (their
    # errors are not independent: one frame's blur moves them together), less where not
    return shift, info / agree.sum() / PAIR_SIGMA_MM**2


def pair_shifts(slices: list[Slice], camera_xy=None, camera_height_mm=None, memo=None) -> dict:
    """{(u, j): pair_shift} for the frames with the part (numbered among themselves), each
    with the ones PAIRS above it. `memo`: {(slice_key, slice_key): pair_shift} of pairs
    measured before (while the scan ran: daemon/processing_child.py), filled with the rest."""
    seen = [s for s in slices if not s.empty]
    memo = {} if memo is None else memo
    out = {}
    for j in range(len(seen)):
        for gap in PAIRS:
            if j - gap >= 0:
                key = (slice_key(seen[j - gap]), slice_key(seen[j]))
                if key not in memo:
                    memo[key] = pair_shift(seen[j - gap], seen[j], camera_xy, camera_height_mm)
                out[(j - gap, j)] = memo[key]
    return out


def slice_key(s: Slice) -> tuple:
    """A slice by its level and its points: two frames' pair shift depends on nothing else."""
    return (s.level, hashlib.blake2b(np.ascontiguousarray(s.P).tobytes(), digest_size=16).digest())


def frame_offsets(slices: list[Slice], camera_xy=None, camera_height_mm=None, pairs=None) -> np.ndarray:
    """(K, 2): each frame's lateral offset in mm (zeros for frames without the part), from
    the shifts between neighbouring frames (`pairs`: pair_shifts', when already known) and a
    prior of PLAY_MM on each offset."""
    K = len(slices)
    seen = [k for k in range(K) if not slices[k].empty]
    m = len(seen)
    A = np.eye(2 * m) / (0.5 * PLAY_MM) ** 2
    b = np.zeros(2 * m)
    if pairs is None:
        pairs = pair_shifts(slices, camera_xy, camera_height_mm)
    for (u, j), (shift, W) in _closed(pairs).items():
        # (t_j - t_u) = shift, weighted by W
        for a, sa in ((j, 1.0), (u, -1.0)):
            b[2 * a : 2 * a + 2] += sa * (W @ shift)
            for c, sc in ((j, 1.0), (u, -1.0)):
                A[2 * a : 2 * a + 2, 2 * c : 2 * c + 2] += sa * sc * W
    t = np.linalg.solve(A, b).reshape(m, 2)
    out = np.zeros((K, 2))
    out[seen] = t - _trend(t)
    return out


def _closed(pairs: dict) -> dict:
    """The pairs whose shifts close a triangle: frames u, u+1, u+2 played by t_u, t_u+1,
    t_u+2 give shift(u, u+2) = shift(u, u+1) + shift(u+1, u+2) to within the pairs' noise.
    A face steep but not vertical (a sphere's cap above its wall) moves its waterline
    outwards by a few hundredths a level, and an arc of it then agrees on a shift that no
    stage made (0.1-0.17 mm on the demo's sphere, frames without any play); two levels apart
    the same face moves twice as far, and its arc and shift are others, so the triangle does
    not close. Only pairs confirmed by a closed triangle count."""
    known = {key: pair for key, pair in pairs.items() if pair[1].any()}
    confirmed = set()
    for u, w in known:
        sides = [(u, w), (u, u + 1), (u + 1, w)]
        if w - u != 2 or not all(side in known for side in sides):
            continue
        gap = known[(u, w)][0] - known[(u, u + 1)][0] - known[(u + 1, w)][0]
        # each side is known across the walls it saw, to the play along them (one straight
        # wall tells nothing along it): the gap is weighed by the three sides' spreads
        spread = sum(np.linalg.inv(known[side][1] + np.eye(2) / PLAY_MM**2) for side in sides)
        if gap @ np.linalg.solve(spread, gap) <= CLOSURE_CHI2:
            confirmed |= set(sides)
    return {key: pairs[key] for key in confirmed}


def _trend(t: np.ndarray) -> np.ndarray:
    """The offsets' slow part: a line through the TREND_FRAMES frames around each. Play is
    new in every frame; what drifts smoothly over many frames is the estimate's own bias (a
    wall edge far from the camera's foot standing higher than the perspective assumed, a
    part leaving the view), or a drift of the stage no waterline can tell from the part's
    shape. Either way it stays (the frames' mean is where the stage says it is)."""
    m = len(t)
    out = np.empty_like(t)
    for j in range(m):
        lo, hi = max(0, j - TREND_FRAMES // 2), min(m, j + TREND_FRAMES // 2 + 1)
        x = np.arange(lo, hi) - j
        if len(x) < 3:
            out[j] = t[lo:hi].mean(axis=0)
            continue
        coef = np.polyfit(x, t[lo:hi], 1)
        out[j] = coef[1]
    return out


def registered(
    slices: list[Slice], camera_xy=None, camera_height_mm=None, memo=None
) -> tuple[list[Slice], np.ndarray]:
    """-> (the slices each moved back by its frame's offset, the offsets (K, 2) in mm). When
    the offsets' rms is under NOTHING_TO_DO_MM, or the shifts do not look like play (_plays;
    the offsets then come back as zeros), the slices come back as they were. `memo`: as
    pair_shifts'."""
    pairs = pair_shifts(slices, camera_xy, camera_height_mm, memo)
    offsets = frame_offsets(slices, camera_xy, camera_height_mm, pairs)
    seen = [k for k, s in enumerate(slices) if not s.empty]
    if np.sqrt(np.mean(np.sum(offsets[seen] ** 2, axis=1))) < NOTHING_TO_DO_MM:
        return slices, offsets
    if not _plays(pairs):
        return slices, np.zeros_like(offsets)
    return [s if s.empty else s.moved(s.P - o, s.z) for s, o in zip(slices, offsets)], offsets


def _plays(pairs: dict) -> bool:
    """Do the shifts between consecutive frames look like play? With offsets t_j new in
    every frame, the steps s_j = t_j - t_(j-1) and s_(j+1) share t_j with opposite signs:
    the sum of s_j . s_(j+1) over the sum of (|s_j|^2 + |s_(j+1)|^2) / 2 is -0.5 for play
    alone, about 0 for shifts that are each their pair's own noise, and +1 for a wall that
    moves out at a steady rate as the ink drops. Measured on the benches' renders: -0.44 to
    +0.04 with the harsh bench's 0.05 mm of play, +0.35 to +0.92 on physics2's renders
    without any. Only a negative sum counts as play."""
    steps = {j: shift for (u, j), (shift, W) in pairs.items() if j - u == 1 and W.any()}
    alike = size = 0.0
    for j, a in steps.items():
        if j + 1 in steps:
            b = steps[j + 1]
            alike += float(a @ b)
            size += 0.5 * float(a @ a + b @ b)
    return size > 0 and alike / size < STEPS_ALIKE
