"""The ETA against the truth: at 25 % of a job, is "time left" within 20 % of what was left?

The daemon's real BenchService scans a cone on the in-memory bench (sim.fakes) and processes it
with the real pipeline in a child (processing.child_process), as on the box. One warm-up job
teaches the box its times (DATA/timings.json, daemon/eta.py); then each measured job's states
are sampled every 0.1 s through the web's EtaSmoother (what the page shows), and at the moment
25 % of that job's actual duration has passed the shown ETA is compared with the time that was
really left, processing included.

    python benches/eta.py [--quick] [--jobs 3]

Measured (--quick, 6 levels of 0.3 s settle, then about a minute of real processing, on the
2-core build machine at a load average of 15 to 19 from other work): shown ETA at 25 % within
15.6, 1.4 and 24.1 %; 1.8, 36.6 and 9.9 %; 15.6, 47.2 and 32.4 % of the time really left. Every
miss is a job whose processing ran far from the learned median (the same job's processing took
50 to 105 s as the other work came and went); the estimate cannot know the CPU it will get. On a
quiet box the processing time repeats and the error is that of the first figure in each run.

Measured 2026-12-03 on the same machine alone (load average under 1; 3 jobs, not --quick, each
about 13 s: 7.5 s of scanning, 5.6-6.4 s of processing): shown ETA at 25 % within 2.7, 1.7 and
8.1 % of the time really left (target 20 %).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from appliance.daemon.service import BenchService
from appliance.sim.fakes import FakeBench
from appliance.web.eta import EtaSmoother

TARGET = 0.20


def run_job(svc, params) -> list[tuple[float, str, float | None, float | None]]:
    """(t, state, daemon eta_s, shown eta) every 0.1 s from start to done."""
    smoother = EtaSmoother()
    t0 = time.monotonic()
    svc.start_scan(params)
    rows = []
    while True:
        st = svc.state()
        now = time.monotonic() - t0
        rows.append((now, st["state"], st["eta_s"], smoother.update(st)))
        if st["state"] in ("done", "failed", "cancelled"):
            if st["state"] != "done":
                raise SystemExit(f"eta bench: the job ended {st['state']}: {st['message']}")
            return rows
        time.sleep(0.1)


def at_quarter(rows):
    total = rows[-1][0]
    t, state, daemon, shown = next(r for r in rows if r[0] >= 0.25 * total)
    left = total - t
    return {
        "total_s": total,
        "t_s": t,
        "state": state,
        "left_s": left,
        "daemon_s": daemon,
        "shown_s": shown,
        "processing_s": total - next(r[0] for r in rows if r[1] == "processing"),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer levels (a shorter scan)")
    ap.add_argument("--jobs", type=int, default=3)
    a = ap.parse_args(argv)
    step = 2.0 if a.quick else 1.0
    params = {
        "name": "eta bench cone",
        "surface": "cone",
        "levels_to_mm": 24.0,
        "levels_from_mm": 2.0,
        "level_step_mm": step,
        "settle_s": 0.3,
    }
    with tempfile.TemporaryDirectory() as tmp:
        svc = BenchService(Path(tmp) / "data", FakeBench("cone"))
        try:
            warm = at_quarter(run_job(svc, params))
            print(
                f"warm-up job (no history): took {warm['total_s']:.1f} s, processing {warm['processing_s']:.1f} s; "
                f"at 25 % it showed {warm['shown_s']} s for {warm['left_s']:.1f} s left"
            )
            errors = []
            for i in range(a.jobs):
                q = at_quarter(run_job(svc, params))
                err_shown = abs(q["shown_s"] - q["left_s"]) / q["left_s"]
                err_daemon = abs(q["daemon_s"] - q["left_s"]) / q["left_s"]
                errors.append(err_shown)
                print(
                    f"job {i + 1}: took {q['total_s']:.1f} s (processing {q['processing_s']:.1f} s); at 25 % "
                    f"({q['t_s']:.1f} s, {q['state']}) left {q['left_s']:.1f} s, shown {q['shown_s']:.1f} s "
                    f"(error {100 * err_shown:.1f} %), daemon's {q['daemon_s']:.1f} s (error {100 * err_daemon:.1f} %)"
                )
        finally:
            svc.close()
    worst = max(errors)
    print(
        f"worst shown-ETA error at 25 %: {100 * worst:.1f} % (target {100 * TARGET:.0f} %): "
        f"{'holds' if worst <= TARGET else 'MISSED'}"
    )
    return 0 if worst <= TARGET else 1


if __name__ == "__main__":
    sys.exit(main())
