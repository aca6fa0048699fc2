"""A scan folder from elsewhere (the web's upload) checked and copied into a new job.

The web server has already unpacked the zip with its own checks (size, paths,
member types). The daemon does not trust that: it reads scan.json with the
scan-format rules (scanfile.load_scan, docs/scan-format.md), and checks every frame it lists
    - is a regular file inside the folder (no symlink, no "..");
    - is a PNG or JPEG whose header says the size scan.json's camera says, 8 bits;
    - adds up, with the others, to at most MAX_BYTES;
and at most MAX_FRAMES frames. Only scan.json and the listed frames are copied
(into JOBS/.import-XXXX on the data disk, renamed to the job's folder when
complete), so a refusal or a failure half-way leaves nothing behind; a kill
half-way leaves the staging folder, which the next start removes (recovery.py). Reading the headers, not
decoding every frame, keeps the check to milliseconds: a whole scan is decoded
by processing anyway, which fails the job with a clear reason if a frame's
body is corrupt.
"""

from __future__ import annotations

import os
import secrets
import shutil
import stat
from pathlib import Path

from ..errors import ScanError
from ..scanfile import Scan, check_frame_header, image_header, load_scan

MAX_FRAMES = 5000
MAX_BYTES = 4 * 1024**3


def check(folder) -> Scan:
    """The scan, if the folder is fit to import; ScanError naming the problem if not."""
    folder = Path(folder)
    scan = load_scan(folder)
    if len(scan.frames) > MAX_FRAMES:
        raise ScanError(
            folder / "scan.json", f"{len(scan.frames)} frames; an import may have at most {MAX_FRAMES}"
        )
    root = folder.resolve()
    total = 0
    seen = set()
    for i, ref in enumerate(scan.frames):
        path = folder / ref.file
        try:
            st = os.lstat(path)
        except OSError:
            raise ScanError(folder / "scan.json", f"frames[{i}] ({ref.file}) is not in the folder") from None
        if not stat.S_ISREG(st.st_mode) or root not in path.resolve().parents:
            raise ScanError(path, "not a plain file inside the scan folder")
        if ref.file in seen:
            raise ScanError(folder / "scan.json", f"frames[{i}] lists {ref.file} a second time")
        seen.add(ref.file)
        total += st.st_size
        if total > MAX_BYTES:
            raise ScanError(folder, f"the frames add up to more than {MAX_BYTES} bytes")
        check_frame_header(path, image_header(path), scan.camera)
    return scan


def copy_into(scan: Scan, job_dir: Path) -> Path:
    """scan.json and the listed frames into job_dir/scan, all or nothing; returns that folder."""
    job_dir = Path(job_dir)
    staging = job_dir.parent / f".import-{secrets.token_hex(6)}"
    try:
        target = staging / "scan"
        target.mkdir(parents=True)
        shutil.copyfile(scan.folder / "scan.json", target / "scan.json")
        for ref in scan.frames:
            dest = target / ref.file
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(scan.folder / ref.file, dest)
        os.rename(staging, job_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return job_dir / "scan"
