"""python -m appliance.daemon.processing_child SCAN OUT OPTIONS_JSON [--follow] (see processing.py).

With --follow the child is started when the capture starts: it imports the processing code
and reads each frame's waterline as the frames land (waterlines.py), and processes the scan
when the daemon writes "go" on its stdin (the capture is over). Stdin closed without "go"
(the scan failed or was cancelled before it was captured): it leaves, exit code 3.
"""

import errno
import json
import select
import sys

from ..errors import InkSliceError

POLL_S = 0.2  # how often a following child looks for new frames
ABANDONED = 3  # exit code: the daemon closed stdin without "go"


def main(argv, truth_for=lambda scan_folder: None):
    """`truth_for(scan_folder)`: the part's ground truth for the statistics, or None (a real scan)."""
    scan, out, options = argv[0], argv[1], json.loads(argv[2])
    from .. import progress
    from ..forks import allow_workers
    from ..process import process_scan

    allow_workers()  # this process has no other thread: the planner may fork its bands
    if "--follow" in argv[3:]:
        go, reader = follow(scan)
        if not go:
            return ABANDONED
        if reader is not None:
            options["waterlines_of"] = reader.finish
            options["pair_memo"] = reader.pair_memo
    try:
        with progress.timed() as clock:
            result = process_scan(scan, out, truth=truth_for(scan), **options)
    except InkSliceError as e:
        print(f"{e.where}: {e.problem}", file=sys.stderr)
        return 2
    except OSError as e:
        if e.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        print(
            f"disk: full while writing the outputs ({e.strerror}); the scan is kept, "
            "free some space and resume",
            file=sys.stderr,
        )
        return 2
    print(
        json.dumps(
            {
                "outputs": result["outputs"],
                "method": result.get("method"),
                "truth": result.get("truth"),
                "phases": {k: [round(v, 2), round(clock.peak_mb[k])] for k, v in clock.seconds.items()},
                "peak_mb": round(progress.peak_mb(), 1),
            }
        )
    )
    return 0


def follow(scan_folder, stdin=None):
    """Read the scan's waterlines as its frames land, until "go" on stdin -> (True, the reader
    with what it read, which reads the rest itself; None if it could not follow); (False,
    None) when stdin closes first."""
    stdin = stdin or sys.stdin
    reader, seen, following = None, None, True
    while True:
        if following:
            try:
                reader, seen = catch_up(scan_folder, reader, seen)
            except (InkSliceError, OSError, ValueError):
                # a frame or scan.json it cannot read now: the processing reads it again
                # from the start and names the problem there
                reader, following = None, False
        ready, _, _ = select.select([stdin], [], [], POLL_S)
        if ready:
            line = stdin.readline()
            if not line:
                return False, None
            if line.strip() == "go":
                return True, reader


def catch_up(scan_folder, reader, seen):
    """Read what scan.json lists now that no later frame can change -> (reader, scan.json's
    mtime read)."""
    from pathlib import Path

    from ..scanfile import load_scan
    from ..waterlines import TopDownReader

    path = Path(scan_folder) / "scan.json"
    try:
        mtime = path.stat().st_mtime_ns
    except FileNotFoundError:
        return reader, seen
    if mtime == seen:
        return reader, seen
    scan = load_scan(scan_folder)
    reader = reader or TopDownReader(scan)
    measure_pairs(reader.read(settled(scan)), reader.pair_memo, scan.camera)
    return reader, mtime


def measure_pairs(waterlines, memo, camera):
    """The shifts between the frames read so far (registration.py), into `memo`: the fit
    then has only the last few pairs left to measure."""
    from ..pipelines import camera_view
    from ..surface.registration import pair_shifts
    from ..surface.slices import check_waterlines

    if not any(wl.loops for wl in waterlines):
        return
    view = camera_view(camera)
    slices, _ = check_waterlines(waterlines)
    pair_shifts(slices, *((view.xy, view.height_mm) if view is not None else (None, None)), memo=memo)


def settled(scan) -> list:
    """The frames that can show a waterline and among which no later frame can come: those at
    or above the upper level of the last step (the runner may still be refining that step,
    between its two levels; daemon/runner.py)."""
    from ..waterlines import waterline_frames

    plan = [f for f in scan.frames if "refines" not in f.extra]
    if len(plan) < 2:
        return []
    upper = plan[-2].level_mm
    return [f for f in waterline_frames(scan) if f.level_mm >= upper]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
