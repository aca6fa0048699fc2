"""The stepover planner in bands on forked workers (cam/bands.py, forks.py)."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance import forks
from appliance.cam import bands
from appliance.cam.bands import Meeting, plan_in_bands
from appliance.cam.cusps import PassProbe
from appliance.cam.cutters import parse_cutter
from appliance.cam.passplan import plan_passes
from appliance.cam.sampling import Sampler
from appliance.cam.scallop import flat_stepover
from appliance.cam.zigzag import FinishSettings, pass_frame
from appliance.errors import InkSliceError
from appliance.progress import TICKER


def _dome(X, Y):
    return np.maximum(0.0, 12.0 - ((X - 25) ** 2 + (Y - 25) ** 2) / 60.0)


def _planner_inputs():
    hm = grid_map(_dome, 0, 50, 0, 50, 1.0)
    st = FinishSettings(parse_cutter("ball6"), scallop=0.05, margin=0.0)
    sampler = Sampler(hm, edge_step=st.resolution / 2)
    e1, e2, (t0, t1), (s0, s1) = pass_frame(sampler, 0.0, 0.0)
    n = int(np.ceil((t1 - t0) / st.resolution - 1e-9)) + 1
    return sampler, st, e1, e2, t0, n, s0, s1


def test_two_planners_from_the_two_ends_meet_on_one_pass_and_hold_the_scallop(monkeypatch):
    sampler, st, e1, e2, t0, n, s0, s1 = _planner_inputs()
    monkeypatch.setattr(bands, "workers", lambda: 2)  # whatever threads the test run has
    passes, tips = plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1)
    alone, alone_tips = plan_passes(sampler, st, e1, e2, t0, n, s0, s1)
    assert passes[0] == s0 and passes[-1] == s1 and np.all(np.diff(passes) > 0)
    # the same planner from each end: its first steps are the ones planned alone from that
    # end (the upper one across -e2), up to where the two met (one pass, kept once)
    down, _ = plan_passes(sampler, st, e1, -e2, t0, n, -s1, -s0)
    assert np.array_equal(passes[:5], alone[:5])
    assert np.array_equal(passes[-5:], -down[:5][::-1])
    # every step within what the planner allows, and the meeting costs at most a pass or two
    cap = min(0.95 * st.cutter.diameter, 1.5 * flat_stepover(st.cutter, st.scallop))
    assert np.max(np.diff(passes)) <= cap + 1e-9
    assert len(alone) - 1 <= len(passes) <= len(alone) + 2
    # each pass's tips are the cutter dropped along that pass
    probe = PassProbe(sampler, st, e1, e2, t0, n)
    for k in (0, len(passes) // 2, len(passes) - 1):
        assert np.array_equal(tips[k], probe.pass_at(passes[k])[1])


def test_the_meeting_does_not_depend_on_which_planner_is_faster(monkeypatch):
    sampler, st, e1, e2, t0, n, s0, s1 = _planner_inputs()
    monkeypatch.setattr(bands, "workers", lambda: 2)
    plans = []
    for slow in (None, bands._Upper, bands._Lower):
        with monkeypatch.context() as m:
            if slow is not None:  # this side takes 20 ms more over every pass
                real = slow.end
                m.setattr(slow, "end", lambda self, *a, real=real: (time.sleep(0.02), real(self, *a))[1])
            plans.append(plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1))
    (p0, t0_), (p1, t1_), (p2, t2_) = plans
    assert np.array_equal(p0, p1) and np.array_equal(p0, p2)
    assert np.array_equal(t0_, t1_) and np.array_equal(t0_, t2_)


def test_the_planners_meet_where_their_passes_cross_at_the_same_clock():
    # each side: its passes in order (the upper's mirrored: s' = -s) and the candidates it
    # had measured by then; the lower decides, from the upper's passes up to its own clock
    meeting = Meeting()
    lower, upper = meeting.lower(), meeting.upper()
    step = 2.0
    assert upper.end(-50.0, 0.0, 0, step) == 0.0  # not met: it goes on
    assert upper.end(-48.0, 0.0, 3, step) == 0.0
    assert lower.end(0.0, 50.0, 0, step) == 50.0  # at clock 0 the upper stood at 50
    for at, clock in ((-47.0, 5), (-44.5, 8), (-43.0, 11)):
        assert upper.end(at, 0.0, clock, step) == 0.0
    assert lower.end(30.0, 50.0, 9, step) == 50.0  # at clock 9 the upper stood at 44.5
    # at clock 9 the upper stood at 44.5 and the lower is past it: they meet on the upper's
    # last pass above the lower's, 47.0; the lower plans up to it
    assert lower.end(45.0, 50.0, 9, step) == 47.0
    assert lower.end(46.0, 50.0, 10, step) == 47.0
    # the upper, asked next, ends there and drops what it placed beyond: 44.5, 43.0, 41.0
    assert upper.end(-41.0, 0.0, 14, step) == -47.0
    assert upper.drop == 3
    # a lower planner whose clock is ahead of the upper's waits for it, unless the upper
    # cannot reach its front by then (a pass costs a candidate at least, moves `step` at most)
    late = Meeting()
    lo, up = late.lower(), late.upper()
    assert up.end(-20.0, 0.0, 0, step) == 0.0
    assert lo.end(1.0, 20.0, 5, step) == 20.0  # 19 mm away, at most 6 x 2 by clock 5
    answer = []
    waiter = threading.Thread(target=lambda: answer.append(lo.end(19.0, 20.0, 6, step)))
    waiter.start()
    waiter.join(0.2)
    assert waiter.is_alive() and not answer
    assert up.end(-18.5, 0.0, 7, step) == 0.0  # clock 7 > 6: the lower knows enough now
    waiter.join(5.0)
    assert answer == [20.0]  # at clock 6 the upper still stood at 20: not met


def test_an_upper_planner_far_ahead_stops_waiting_for_a_lower_one_that_was_killed():
    meeting = Meeting()
    up = meeting.upper()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # reaped: no such process any more
    meeting.pid[0] = dead.pid  # as the lower planner's worker writes it when it begins
    # 100 candidates measured, none by the lower: far beyond LEAD, so it waits for the
    # lower until it sees that process gone (every 0.1 s of waiting)
    answer = []
    waiter = threading.Thread(target=lambda: answer.append(up.end(-50.0, 0.0, 100, 2.0)), daemon=True)
    waiter.start()
    waiter.join(5.0)
    assert answer == [0.0] and meeting.ended[0] == 1.0
    assert bands._alive(os.getpid(), 0.0) and not bands._alive(dead.pid, 0.0)
    assert bands._alive(0, 1.0) and not bands._alive(0, 61.0)  # not begun: at most a minute


def test_a_failing_upper_planner_does_not_leave_the_lower_one_waiting(monkeypatch):
    sampler, st, e1, e2, t0, n, s0, s1 = _planner_inputs()
    monkeypatch.setattr(bands, "workers", lambda: 2)
    real = bands.plan_passes

    def upper_fails(*a, meet=None, **k):
        if a[3][1] < 0:  # the upper planner plans across -e2
            raise ValueError("the map went away")
        return real(*a, meet=meet, **k)

    monkeypatch.setattr(bands, "plan_passes", upper_fails)
    with pytest.raises(ValueError, match="the map went away"):
        plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1)


def test_without_permission_or_with_another_thread_alive_the_planner_stays_in_one_band(monkeypatch):
    main = threading.main_thread()
    alive = [main]
    monkeypatch.setattr(threading, "enumerate", lambda: list(alive))
    assert forks.workers() == 1  # a library call: nobody allowed it
    with forks.workers_allowed(2):
        assert forks.workers() == 2
        alive.append(threading.Thread(name=TICKER))  # the command line's progress bar
        assert forks.workers() == 2
        alive.append(threading.Thread(name="web"))
        assert forks.workers() == 1
    alive[:] = [main]
    assert forks.workers() == 1  # the block left the process as it was


def test_a_failing_or_killed_worker_is_an_error_naming_it():
    def boom():
        raise ValueError("no such pass")

    with pytest.raises(InkSliceError, match="ValueError: no such pass"):
        forks.in_workers([lambda: 1, boom])

    def killed():
        os.kill(os.getpid(), signal.SIGKILL)

    with pytest.raises(InkSliceError, match="signal 9"):
        forks.in_workers([lambda: 1, killed])
    assert forks.in_workers([lambda: "here", lambda: "there"]) == ["here", "there"]


def test_in_parts_splits_the_items_by_weight_one_part_a_worker_and_joins_them_in_order(monkeypatch):
    monkeypatch.setattr(forks, "workers", lambda: 2)

    def work(a, b):
        return [(i, a, b, os.getpid()) for i in range(a, b)]

    weights = [5.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    out = forks.in_parts(work, weights, forks.joined)
    assert [x[0] for x in out] == list(range(6))
    assert {(x[1], x[2]) for x in out} == {(0, 1), (1, 6)}  # 5 against 5
    assert out[0][3] == os.getpid() != out[-1][3]  # the second part ran in a forked worker
    assert forks.in_parts(work, [], lambda parts: parts) == [[]]  # nothing to split: one call
    monkeypatch.setattr(forks, "workers", lambda: 1)
    assert {x[3] for x in forks.in_parts(work, weights, lambda parts: parts[0])} == {os.getpid()}


def test_each_in_parts_gives_each_item_its_own_result_in_order(monkeypatch):
    monkeypatch.setattr(forks, "workers", lambda: 2)
    out = forks.each_in_parts(lambda i: (i * i, os.getpid()), [1.0, 1.0, 1.0, 1.0])
    assert [v for v, _ in out] == [0, 1, 4, 9]
    assert out[0][1] == os.getpid() != out[-1][1]  # the later items ran in a forked worker
    assert forks.each_in_parts(lambda i: i, []) == []


def test_a_finish_in_parts_on_two_cores_is_the_finish_in_one(monkeypatch):
    """With the stepover given (no planner), every other piece of a finish runs in parts
    where forking is allowed: the mid-point drops, the pass ends' fine lines, the
    refinement and the links. Its moves come out the same, but for the last digits of a
    float32: a drop reads its slab in float32 relative to the highest height of the lines
    dropped with it, and in parts a line is dropped with others (1e-6 mm here)."""
    from appliance.cam.zigzag import finishing

    hm = grid_map(_dome, 0, 50, 0, 50, 1.0)
    st = FinishSettings(parse_cutter("ball6"), scallop=0.05, stepover=1.5)
    finishes = []
    for n in (1, 2):
        monkeypatch.setattr(forks, "workers", lambda n=n: n)
        finishes.append(finishing(Sampler(hm, edge_step=st.resolution / 2), st))
    one, two = finishes
    assert len(one.passes) > 30 and len(one.runs) < len(one.passes)  # passes joined by links
    assert len(one.runs) == len(two.runs) and one.linked == two.linked
    assert all(a.shape == b.shape for a, b in zip(one.runs, two.runs))
    assert max(float(np.max(np.abs(a - b))) for a, b in zip(one.runs, two.runs)) < 1e-5
