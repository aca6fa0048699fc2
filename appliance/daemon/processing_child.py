"""python -m appliance.daemon.processing_child SCAN OUT OPTIONS_JSON (see processing.py)."""

import errno
import json
import sys

from ..errors import InkSliceError


def main(argv, truth_for=lambda scan_folder: None):
    """`truth_for(scan_folder)`: the part's ground truth for the statistics, or None (a real scan)."""
    scan, out, options = argv[0], argv[1], json.loads(argv[2])
    from .. import progress
    from ..process import process_scan

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
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
