"""Firmware bench: memory use, step rate, jitter and acceleration profile.

    .venv/bin/python benches/firmware.py [--quick]

Figures (issue 6 acceptance):
  1. avr-size: flash and RAM use of the ATmega328P firmware (target <= 50 % each).
  2. For a ladder of max_rate settings, a long move on the simulated bench
     with the host polling status ('?') as fast as the line allows, so the
     UART interrupts compete with the step interrupt the whole time.  Every
     STEP rising edge is timestamped in simulated cycles (16 per us).  Jitter
     = the largest |measured - planned| step interval over the whole move,
     where "planned" is the firmware's own plan (re-computed here from the
     same integer maths as planner.c).  The figure: the highest rate reached
     with jitter < 2 us (target >= 20 kHz).
  3. The acceleration profile at the default settings: measured step-rate
     vs time against the ideal trapezoid (v = a t up to max_rate), as the
     max and RMS deviation in % of max_rate over the ramps, and the move time
     against the ideal trapezoid's.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from appliance.hw.stage import SerialStage
from appliance.sim.hil import SimulatedBench, build

F_CPU = 16_000_000
CYC_PER_TICK = 8  # Timer1 at clk/8
K = 48  # RAMP_SEGMENTS
TICK_HZ = 2_000_000
MIN_IV, MAX_IV = 40, 65535


# ---- the firmware's planner, same integer maths (planner.c) ----
def interval_for_rate(rate):
    iv = (TICK_HZ + rate // 2) // rate
    return min(MAX_IV, max(MIN_IV, iv))


def ramp_build(v, a):
    top = interval_for_rate(v)
    steps, ivs = [], []
    prev_s, prev_end = 0, 0
    for i in range(K):
        s = ((i + 1) ** 2 * v * v + a * K * K) // (2 * a * K * K)
        n = s - prev_s
        if n == 0:
            steps.append(0), ivs.append(MAX_IV)
            continue
        n = min(n, 65535)
        iv = ((i + 1 - prev_end) * TICK_HZ * v + (a * K * n) // 2) // (a * K * n)
        ivs.append(min(MAX_IV, max(top, iv)))
        steps.append(n)
        prev_s, prev_end = s, i + 1
    return steps, ivs, top


def planned_intervals(distance, v, a):
    steps, ivs, top = ramp_build(v, a)
    want = max(interval_for_rate(v), top)
    climbed, m = 0, 0
    while m < K and ivs[m] > want and 2 * (climbed + steps[m]) <= distance:
        climbed += steps[m]
        m += 1
    if m < K and ivs[m] > want:
        j = m
        while j < K - 1 and steps[j] == 0:
            j += 1
        cruise = max(ivs[j], want)
    else:
        cruise = want
    out = []
    for k in range(m):
        out += [ivs[k]] * steps[k]
    out += [cruise] * (distance - 2 * climbed)
    for k in reversed(range(m)):
        out += [ivs[k]] * steps[k]
    return np.array(out, dtype=np.int64)


# ---- measurement ----
def read_edges(path):
    rec = np.fromfile(path, dtype=np.dtype([("cycle", "<u8"), ("pin", "u1"), ("level", "u1"), ("pad", "V6")]))
    rises = rec["cycle"][(rec["pin"] == 0) & (rec["level"] == 1)].astype(np.int64)
    return rises


def hammer_status(stage, stop):
    """Poll status back to back: RX and TX interrupts the whole time."""
    while not stop.is_set():
        try:
            stage.raw_status()
        except Exception:
            pass


def measure_move(rate, accel, distance, speed, load=True):
    with SimulatedBench(speed=speed, stage_mm=1.5) as bench, tempfile.TemporaryDirectory() as tmp:
        stage = SerialStage(bench.port, poll_interval=0.001)
        stage.set_setting("accel", accel)
        stage.set_setting("max_rate", rate)
        stage.home()
        edges = Path(tmp) / "edges.bin"
        bench.record_edges(edges)
        stop = threading.Event()
        th = threading.Thread(target=hammer_status, args=(stage, stop), daemon=True)
        if load:
            th.start()
        start = stage._target
        stage.move_to_steps(start + distance, timeout=120)
        stop.set()
        if load:
            th.join()
        bench.record_edges(None)
        polls = (stage.counters["status_polls"], bench.stats()["rx_overruns"])
        stage.close()
        rises = read_edges(edges)
    return rises, polls


def jitter_for_rate(rate, accel, distance, speed):
    rises, polls = measure_move(rate, accel, distance, speed)
    plan = planned_intervals(distance, rate, accel) * CYC_PER_TICK
    measured = np.diff(rises)
    plan = plan[1 : len(measured) + 1]
    if len(rises) != distance:
        return None, f"{len(rises)} edges for {distance} steps"
    dev_us = np.abs(measured - plan) / 16.0
    cruise = plan == plan.min()
    achieved = F_CPU / np.median(measured[cruise])
    return dict(
        rate=rate,
        jitter_us=float(dev_us.max()),
        jitter_p99_us=float(np.percentile(dev_us, 99)),
        achieved_hz=float(achieved),
        polls=polls[0],
        overruns=polls[1],
    ), None


def accel_profile(rate, accel, distance, speed):
    rises, _ = measure_move(rate, accel, distance, speed, load=False)
    first_iv = planned_intervals(distance, rate, accel)[0] * CYC_PER_TICK
    t = (rises - (rises[0] - first_iv)) / F_CPU  # seconds since the timer started
    dt = np.diff(t)
    tm = (t[1:] + t[:-1]) / 2
    v_meas = 1.0 / dt
    t_acc = rate / accel
    T_ideal = distance / rate + t_acc  # trapezoid from rest to rest
    v_ideal = np.minimum.reduce([accel * tm, np.full_like(tm, rate), accel * (T_ideal - tm)])
    ramps = (tm < t_acc) | (tm > T_ideal - t_acc)
    dev = (v_meas - v_ideal) / rate * 100
    return dict(
        max_dev_pct=float(np.abs(dev[ramps]).max()),
        rms_dev_pct=float(np.sqrt(np.mean(dev[ramps] ** 2))),
        time_s=float(t[-1]),
        ideal_time_s=T_ideal,
        time_err_pct=float((t[-1] - T_ideal) / T_ideal * 100),
    )


def avr_size():
    out = subprocess.run(
        ["avr-size", "-C", "--mcu=atmega328p", str(build() / "inkslice-stepper.elf")],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    flash = re.search(r"Program:\s+(\d+) bytes \(([\d.]+)% Full\)", out)
    ram = re.search(r"Data:\s+(\d+) bytes \(([\d.]+)% Full\)", out)
    return int(flash[1]), float(flash[2]), int(ram[1]), float(ram[2])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="three rates and a shorter profile move")
    args = ap.parse_args()

    fb, fp, rb, rp = avr_size()
    print(
        f"avr-size: flash {fb} B = {fp:.1f} % of 32 KB, RAM {rb} B = {rp:.1f} % of 2 KB "
        f"(target <= 50 % each: {'PASS' if fp <= 50 and rp <= 50 else 'FAIL'})"
    )

    t = time.monotonic()
    with SimulatedBench(speed=1.0) as bench:
        stage = SerialStage(bench.port)
        stage.close()
    print(f"SimulatedBench start + SerialStage identify: {time.monotonic() - t:.2f} s (target < 2 s)")

    rates = [10000, 20000, 40000] if args.quick else [10000, 15000, 20000, 25000, 30000, 35000, 40000]
    accel = 1_000_000
    best = 0
    print(f"\nstep timing under continuous status polling, accel {accel} steps/s^2, sim at real time:")
    print(f"{'max_rate':>9} {'achieved':>9} {'jitter max':>11} {'p99':>7} {'polls':>6} {'rx overruns':>11}")
    for r in rates:
        distance = max(8000, r // 2)  # >= 0.5 s of cruise
        res, problem = jitter_for_rate(r, accel, distance, speed=1.0)
        if res is None:
            print(f"{r:>9} failed: {problem}")
            continue
        ok = res["jitter_us"] < 2.0 and res["overruns"] == 0
        if ok:
            best = max(best, res["achieved_hz"])
        print(
            f"{r:>9} {res['achieved_hz']:>9.0f} {res['jitter_us']:>9.2f}us {res['jitter_p99_us']:>5.2f}us "
            f"{res['polls']:>6} {res['overruns']:>11}  {'ok' if ok else 'FAIL'}"
        )
    print(
        f"highest step rate reached with jitter < 2 us: {best:.0f} Hz "
        f"(target >= 20000: {'PASS' if best >= 20000 else 'FAIL'}; max_rate is capped at 40000 by codes.def)"
    )

    d = 8000 if args.quick else 32000
    prof = accel_profile(16000, 80000, d, speed=0)
    print(f"\nacceleration profile, default settings (16000 steps/s, 80000 steps/s^2), {d}-step move:")
    print(
        f"  velocity vs ideal trapezoid over the ramps: max {prof['max_dev_pct']:.2f} % of max_rate, "
        f"RMS {prof['rms_dev_pct']:.2f} %"
    )
    print(
        f"  move time {prof['time_s']:.4f} s vs ideal {prof['ideal_time_s']:.4f} s ({prof['time_err_pct']:+.2f} %)"
    )


if __name__ == "__main__":
    main()
