"""The stepover planner in bands on forked workers (cam/bands.py, cam/forks.py)."""

import os
import signal
import threading

import numpy as np
import pytest
from cam_helpers import grid_map

from appliance.cam import bands, forks
from appliance.cam.bands import band_bounds, plan_in_bands
from appliance.cam.cutters import parse_cutter
from appliance.cam.passplan import plan_passes
from appliance.cam.sampling import Sampler
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


def test_bands_split_the_footprint_into_equal_areas_and_never_thinner_than_the_minimum():
    sampler, _, _, e2, _, _, s0, s1 = _planner_inputs()
    mid = band_bounds(sampler, e2, s0, s1, 2)
    assert mid[0] == s0 and mid[-1] == s1 and len(mid) == 3
    assert mid[1] == pytest.approx(25.0, abs=1.0)  # the dome is symmetric about y 25
    assert band_bounds(sampler, e2, s0, s0 + 30, 2) == [s0, s0 + 30]  # two 15 mm bands: one
    assert band_bounds(sampler, e2, s0, s1, 1) == [s0, s1]


def test_banded_plan_is_each_band_planned_alone_joined_on_the_boundary_pass(monkeypatch):
    sampler, st, e1, e2, t0, n, s0, s1 = _planner_inputs()
    monkeypatch.setattr(bands, "workers", lambda: 2)  # whatever threads the test run has
    passes, tips = plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1)
    b = band_bounds(sampler, e2, s0, s1, 2)[1]
    low, low_tips = plan_passes(sampler, st, e1, e2, t0, n, s0, b)
    high, high_tips = plan_passes(sampler, st, e1, e2, t0, n, b, s1)
    # the low band ends on the boundary and the high one starts there: that pass once
    assert low[-1] == b == high[0]
    assert np.array_equal(passes, np.concatenate([low, high[1:]]))
    assert np.array_equal(tips, np.concatenate([low_tips, high_tips[1:]]))
    assert np.all(np.diff(passes) > 0) and passes[0] == s0 and passes[-1] == s1


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
