"""Soak: 1,000 random moves through a line that corrupts, drops and duplicates
1 % of the bytes in both directions, with 3 resets of the MCU mid-move.

Acceptance (issue 6): every move is executed exactly once -- after every
move the stage's counted steps equal the commanded position, including after
each re-home -- and no driver command takes longer than its budget.

Under load (issue 19: 5 runs in a row beside 2 busy processes) the simulated
MCU runs slower and its replies come late: the driver's budget follows the
measured round trip instead of a fixed 3 s (hw/stage.py). A damaged reply is
resent at once: waited out as silence, it made the waits grow until a status
poll had four tries in its budget, which failed 2 of 4 CI runs, and the 1000
moves took ~80 s (now ~12 s). The figures printed
are the run's time, the worst round trip and the largest budget given."""

import random
import threading
import time

import pytest

from appliance.hw.roundtrip import MAX_WAIT_S
from appliance.hw.stage import ATTEMPTS, SerialStage
from appliance.sim.hil import SimulatedBench

MOVES = 1000
FAULT_RATE = 0.01
RESETS = 3


@pytest.mark.slow
@pytest.mark.simavr
def test_1000_moves_through_a_noisy_line_and_3_resets_each_execute_exactly_once(fw_build):
    rng = random.Random(20261122)
    t0 = time.monotonic()
    with SimulatedBench(speed=0, seed=6) as bench:
        stage = SerialStage(bench.port, timeout=3.0, reply_timeout=0.08)
        try:
            stage.home()
            homed_at = bench.stage_position_steps()
            bench.set_faults(FAULT_RATE)
            reset_moves = set(rng.sample(range(20, MOVES), RESETS))
            position = homed_at
            slowest = 0.0
            timers = []
            for i in range(MOVES):
                target = min(150000, max(1600, position + rng.randint(-1600, 1600)))
                if i in reset_moves:  # pull the reset line while this move is under way
                    t = threading.Timer(rng.uniform(0.0005, 0.004), bench.reset_mcu)
                    t.start()
                    timers.append(t)
                started = time.monotonic()
                stage.move_to_steps(target, timeout=60.0)
                slowest = max(slowest, time.monotonic() - started)
                counted = bench.stage_position_steps()
                assert counted == target, f"move {i}: commanded {target} steps, stage counted {counted}"
                position = target
            for t in timers:
                t.join()
            s = bench.stats()
            c = stage.counters
        finally:
            stage.close()
    took = time.monotonic() - t0
    faults = {k: v for k, v in s.items() if k.startswith(("rx_", "tx_"))}
    print(f"\nsoak: {MOVES} moves in {took:.1f} s; resets {s['resets']}; wire {faults}")
    print(f"driver: {c}; slowest move {slowest:.2f} s")
    print(
        f"worst round trip {c['worst_round_trip_s'] * 1000:.0f} ms; longest command "
        f"{c['longest_command_s']:.2f} s of a budget up to {c['longest_budget_s']:.2f} s"
    )
    assert s["resets"] == RESETS
    assert c["rehomes"] >= RESETS  # every reset was noticed and recovered from
    assert c["idle_off_target"] == 0  # no acknowledged move was ever found not done
    assert c["over_budget"] == 0  # no command outlived its budget,
    assert c["longest_command_s"] < stage.timeout / 3  # noise costs tries, not waits: none came near it,
    assert c["longest_budget_s"] <= max(stage.timeout, ATTEMPTS * MAX_WAIT_S)  # and that stays bounded
    assert s["stalls"] == 0
    assert s["rx_overruns"] == 0  # a real 2-byte receive FIFO would have kept up
    injected = sum(v for k, v in faults.items() if not k.endswith("bytes"))
    total = s["rx_bytes"] + s["tx_bytes"]
    assert 0.005 < injected / total < 0.02  # the line really was that bad
