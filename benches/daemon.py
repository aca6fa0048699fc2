"""Peak memory of the daemon during a 2048 x 1536, 80-level scan (issue 7:
under 250 MB, so a Pi with 1 GB runs it comfortably).

The daemon runs as its own process (`inkslice daemon --sim fake`) and its
peak resident memory is read from /proc/PID/status (VmHWM) when the scan is
done. Its camera replays frames rendered beforehand by the virtual bench, one
PNG per level: on the real bench the frame comes from V4L2 and the renderer
does not run inside the daemon, so rendering in-process would measure the
renderer, not the daemon. Processing runs in a child process (see
appliance/daemon/processing.py); its peak is printed separately.

    .venv/bin/python benches/daemon.py            # 2048 x 1536, 80 levels (~2-3 min)
    .venv/bin/python benches/daemon.py --quick    # 640 x 480, 10 levels, dissertation pipeline

Measured 2026-11-22 (shared 2-core box, load ~15): daemon peak 122 MB (idle 96 MB); the
processing child 481 MB with the default pipeline (440 MB with --pipeline seed).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import cv2

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchkit import bench_tmp, proc_status_mb, start_daemon  # noqa: E402

from appliance.daemon.levels import LevelPlan  # noqa: E402
from appliance.daemon.settings import DEFAULTS, validate  # noqa: E402
from appliance.sim.fakes import LevelSeededCamera, replay_name, small_rig  # noqa: E402
from appliance.sim.surfaces import get  # noqa: E402

LIMIT_MB = 250.0


def levels_of(params):
    plan = LevelPlan(validate(DEFAULTS, params))
    out, frames = [], []

    class F:  # just enough of a FrameRef for the plan
        def __init__(self, target, step):
            self.level_mm, self.extra = target, {"target_mm": target, "step_mm": step}

    while (nxt := plan.next_target(frames)) is not None:
        out.append(nxt[0])
        frames.append(F(*nxt))
    return out


def render(folder, levels, rig, surface):
    folder.mkdir(parents=True, exist_ok=True)
    for level in levels:
        cam = LevelSeededCamera(surface, rig, lambda level=level: level)
        cv2.imwrite(str(folder / replay_name(level)), cam.capture(), [cv2.IMWRITE_PNG_COMPRESSION, 1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="640 x 480, 10 levels")
    ap.add_argument("--keep", action="store_true", help="keep the data folder and print where it is")
    ap.add_argument(
        "--pipeline",
        default=None,
        help="processing pipeline for the job (default: processing's own; --quick: seed, "
        "since our finishing toolpath takes minutes on a busy machine)",
    )
    args = ap.parse_args()
    w, h, n = (640, 480, 10) if args.quick else (2048, 1536, 80)
    surface = get("sphere")
    # the range must reach over the sphere (30 mm): a top frame that still shows the part sends
    # the scan higher than the replayed frames go
    step = 0.4 if not args.quick else 3.5
    params = {
        "name": "memory bench",
        "surface": surface.name,
        "levels_from_mm": 0.0,
        "levels_to_mm": round(step * (n - 1), 3),
        "level_step_mm": step,
        "settle_s": 0.0,
        "refine_mm": 0.0,  # no bisected steps: the replay holds the planned levels only
    }
    pipeline = args.pipeline or ("seed" if args.quick else "")
    if pipeline:
        params["pipeline"] = pipeline
    levels = levels_of({k: v for k, v in params.items() if k in DEFAULTS})
    assert len(levels) == n, len(levels)
    with bench_tmp(args.keep, "inkslice-bench-daemon-") as tmp:
        t0 = time.monotonic()
        render(tmp / "replay", levels, small_rig(w, h), surface)
        print(f"rendered {n} frames of {w} x {h} in {time.monotonic() - t0:.1f} s")
        proc, client = start_daemon(
            tmp,
            "--sim",
            "fake",
            "--replay",
            str(tmp / "replay"),
            "--frame",
            f"{w}x{h}",
            "--surface",
            surface.name,
        )
        idle_mb = proc_status_mb(proc.pid, "VmRSS")
        t0 = time.monotonic()
        job_id = client.start_scan(params)
        rss_max, t_scan = 0.0, None
        while True:
            st = client.state()
            rss_max = max(rss_max, proc_status_mb(proc.pid, "VmRSS"))
            if st["state"] == "processing" and t_scan is None:
                t_scan = time.monotonic() - t0
            if st["state"] in ("done", "failed", "cancelled") and client.job(job_id)["status"] == st["state"]:
                break
            time.sleep(0.1)
        total = time.monotonic() - t0
        hwm = proc_status_mb(proc.pid, "VmHWM")
        job = client.job(job_id)
        events = [e["message"] for e in client.events(job_id) if e["kind"] == "processed"]
        proc.terminate()
        proc.wait(timeout=30)
        if job["status"] != "done":
            sys.exit(f"scan {job['status']}: {job['reason']}")
        print(f"scan: {job['levels_done']} levels of {w} x {h}, capture {t_scan:.1f} s, total {total:.1f} s")
        print(f"daemon RSS idle: {idle_mb:.1f} MB")
        print(
            f"daemon peak RSS (VmHWM) during the scan: {hwm:.1f} MB  (limit {LIMIT_MB:.0f} MB: "
            f"{'OK' if hwm < LIMIT_MB else 'OVER'})"
        )
        print(f"processing child: {events[0] if events else 'no figure'}")
        print(
            json.dumps(
                {
                    "width": w,
                    "height": h,
                    "levels": job["levels_done"],
                    "daemon_peak_mb": round(hwm, 1),
                    "daemon_idle_mb": round(idle_mb, 1),
                    "capture_s": round(t_scan, 1),
                }
            )
        )
        return 0 if hwm < LIMIT_MB else 1


if __name__ == "__main__":
    sys.exit(main())
