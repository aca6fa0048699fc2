"""Hostile input to the CLI: each case is refused with one line and the right exit code.

One row per case (issue 19, items 9 and 10, and more): how the bad input is made
from a small valid workspace, the command, the expected exit code and a fragment of
the one-line message. Every row is run through the real CLI (`appliance.cli.main`,
in-process: the same code as the `inkslice` script, without a new interpreter per
case) and must give
  - the expected exit code (2: bad input; 1: `verify` found the program cuts the part),
  - exactly one line on stderr, `inkslice: error: WHERE: PROBLEM`, with the fragment,
  - no traceback (an exception escaping main() fails the row with its traceback),
  - the output folder byte for byte as it was.
The workspace: a tiny valid scan (the hand-made cone of scan_helpers, 8 frames of
240 x 240), an output folder holding an earlier run's files, a valid height map
and a G-code program. Nothing computes: every refusal comes before the work, so the
whole table takes seconds. The last test prints how many cases were tried.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from cam_helpers import grid_map
from scan_helpers import write_cone_scan

from appliance.cli import main

TRIED: list[str] = []
# a lens for the hand-made cone's 240 x 240 frames (it has none: its homography is orthographic)
K_CONE = [[1000.0, 0.0, 120.0], [0.0, 1000.0, 120.0], [0.0, 0.0, 1.0]]


# -- the workspace ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    """Built once: the scan, a height map (a 20 x 20 mm dish on a 2 mm plinth), a program."""
    root = tmp_path_factory.mktemp("valid")
    write_cone_scan(root / "scan")
    from appliance.outputs import write_heightmap_csv

    write_heightmap_csv(
        root / "map.csv", grid_map(lambda X, Y: 2 + 0.01 * ((X - 10) ** 2 + (Y - 10) ** 2), 0, 20, 0, 20, 0.5)
    )
    (root / "prog.gcode").write_text("G21 G90\nG0 Z30\nG0 X5 Y5\nG1 Z25 F200\nG1 X15 Y15\nG0 Z30\nM2\n")
    return root


@pytest.fixture
def work(valid, tmp_path):
    shutil.copytree(valid, tmp_path, dirs_exist_ok=True)
    out = tmp_path / "out"  # an earlier run's outputs, which a refusal must keep
    out.mkdir()
    (out / "heightmap.csv").write_text("x,y,z\n0,0,1\n")
    (out / "toolpath.gcode").write_text("G21 G90\nM2\n")
    (out / "error_inkslice_fit.png").write_bytes(b"\x89PNG\r\n\x1a\nold")
    return tmp_path


def read_only_folder(tmp: Path) -> Path | None:
    """A folder nobody may write in: a 0555 one (enough unless we are root), or /proc/sys."""
    ro = tmp / "read-only"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    for candidate in (ro, Path("/proc/sys")):
        if candidate.is_dir() and not os.access(candidate, os.W_OK):
            return candidate
    return None


def folder_hash(folder: Path) -> dict:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


# -- ways to break the workspace ------------------------------------------------------------


def scan_json(edit):
    """Build step: load the scan's scan.json, let `edit(doc)` change it in place, write it back."""

    def build(w: Path):
        path = w / "scan" / "scan.json"
        doc = json.loads(path.read_text())
        edit(doc)
        path.write_text(json.dumps(doc))

    return build


def camera(**changes):
    return scan_json(lambda d: d["camera"].update(changes))


def lens(K=K_CONE, dist=(0, 0, 0, 0, 0)):
    return camera(K=K, dist=list(dist))


def every_level(value):
    def edit(d):
        for f in d["frames"]:
            f["level_mm"] = value

    return scan_json(edit)


def first_level(value):
    return scan_json(lambda d: d["frames"][0].update(level_mm=value))


def raw_scan_json(text: str | bytes):
    def build(w):
        path = w / "scan" / "scan.json"
        path.write_bytes(text if isinstance(text, bytes) else text.encode())

    return build


def deep_inside(depth):
    return scan_json(lambda d: d.update(notes=json.loads("[" * depth + "]" * depth)))


def heightmap(rows: str):
    def build(w):
        (w / "map.csv").write_text("x,y,z\n" + rows)

    return build


def symlink_frame_outside(w):
    outside = w / "elsewhere.png"
    shutil.copy(w / "scan/frames/0003.png", outside)
    (w / "scan/frames/0003.png").unlink()
    (w / "scan/frames/0003.png").symlink_to(outside)


def symlink_frames_folder_outside(w):
    shutil.move(w / "scan/frames", w / "elsewhere")
    (w / "scan/frames").symlink_to(w / "elsewhere")


def symlink_scan_json_outside(w):
    shutil.move(w / "scan/scan.json", w / "elsewhere.json")
    (w / "scan/scan.json").symlink_to(w / "elsewhere.json")


def frame_16_bit(w):
    cv2.imwrite(str(w / "scan/frames/0003.png"), np.zeros((240, 240), np.uint16))


def frame_is_a_folder(w):
    (w / "scan/frames/0003.png").unlink()
    (w / "scan/frames/0003.png").mkdir()


def out_is_a_file(w):
    shutil.rmtree(w / "out")
    (w / "out").write_text("my notes, not an output folder\n")


def both(*steps):
    def build(w):
        for s in steps:
            s(w)

    return build


HORIZON_ACROSS = [[0.25, 0, 0], [0, -0.25, 60], [0, 0.01, -1.0]]  # w = 0.01 v - 1: zero at v = 100
CONE_H = [[0.25, 0, 0], [0, -0.25, 60], [0, 0, 1]]
FOLDING_LENS = (-100.0, 0, 0, 0, 0)  # r (1 - 100 r^2) turns back at r = 0.058: inside the frame

P = ("process", "{scan}", "-o", "{out}")
T = ("toolpath", "{map}", "-o", "{out}/toolpath.gcode")
V = ("verify", "{gcode}", "--against", "{map}", "--cutter", "ball6", "--png", "{out}/verify.png")


@dataclass
class Case:
    name: str
    build: Callable | None
    argv: tuple
    code: int
    says: str


CASES = [
    # -- issue 19 item 9: tracebacks in `process` ------------------------------------------
    Case(
        "scan.json nested 200 k deep",
        raw_scan_json("[" * 200_000 + "]" * 200_000),
        P,
        2,
        "scan.json: nests objects or lists deeper than",
    ),
    Case(
        "declared width and height of 10^6",
        camera(width=10**6, height=10**6),
        P,
        2,
        "1000000 x 1000000 pixels is more than a frame may have",
    ),
    Case("K with fx = 0", lens(K=[[0, 0, 120], [0, 1000, 120], [0, 0, 1]]), P, 2, "focal lengths fx, fy > 0"),
    Case("K all zeros", lens(K=[[0] * 3] * 3), P, 2, "focal lengths fx, fy > 0"),
    Case("dist = 1e30", camera(K=K_CONE, dist=1e30), P, 2, "camera.dist must be 4, 5, 8, 12 or 14"),
    Case("dist with a coefficient of 1e30", lens(dist=(1e30, 0, 0, 0, 0)), P, 2, "a coefficient of 1e+30"),
    Case(
        "tank given as a string", scan_json(lambda d: d.update(tank="31400")), P, 2, "tank must be an object"
    ),
    Case("tank given as a list", scan_json(lambda d: d.update(tank=[31400])), P, 2, "tank must be an object"),
    Case("OUT is an existing file", out_is_a_file, P, 2, "not a folder"),
    Case(
        "OUT on a read-only file system",
        None,
        ("process", "{scan}", "-o", "{ro}/out"),
        2,
        "cannot be written",
    ),
    Case(
        "toolpath on a 4-line height map with 1e9 mm extents",
        heightmap("0,0,1\n1e9,0,1\n0,1e9,1\n1e9,1e9,1\n"),
        T,
        2,
        "map.csv: spans 1e+09 mm in x",
    ),
    Case(
        "verify on a 4-line height map with 1e9 mm extents",
        heightmap("0,0,1\n1e9,0,1\n0,1e9,1\n1e9,1e9,1\n"),
        V,
        2,
        "map.csv: spans 1e+09 mm in x",
    ),
    # -- issue 19 item 10: wrong successes ---------------------------------------------------
    Case(
        "every level at -1000 mm",
        every_level(-1000.0),
        P,
        2,
        "frames[0].level_mm is -1000 mm: below the base",
    ),
    Case(
        "a homography whose horizon crosses the image",
        camera(homography=HORIZON_ACROSS),
        P,
        2,
        "horizon across",
    ),
    Case(
        "a duplicated level",
        scan_json(lambda d: d["frames"][3].update(level_mm=d["frames"][2]["level_mm"])),
        P,
        2,
        "frames[2] and frames[3] are both at level 15 mm",
    ),
    Case(
        "height_mm 0", camera(height_mm=0), P, 2, "camera.height_mm is 0: the camera must be above the liquid"
    ),
    Case("height_mm -300", camera(height_mm=-300), P, 2, "camera.height_mm is -300"),
    Case(
        "a level of 1e300",
        first_level(1e300),
        P,
        2,
        "frames[0].level_mm is 1e+300 mm: beyond the stage's travel",
    ),
    Case(
        "a tank area of 0",
        scan_json(lambda d: d.update(tank={"inner_area_mm2": 0})),
        P,
        2,
        "tank.inner_area_mm2 is 0: a tank's inner area must be > 0",
    ),
    Case(
        "a tank whose ink falls 'yes'",
        scan_json(lambda d: d.update(tank={"inner_area_mm2": 22500, "surface_falls": "yes"})),
        P,
        2,
        "tank.surface_falls must be true or false",
    ),
    Case(
        "toolpath: two rows with the same x,y and different z",
        heightmap("0,0,1\n1,0,1\n0,1,1\n1,1,1\n0,0,3\n"),
        T,
        2,
        "give x=0, y=0 two heights",
    ),
    Case(
        "verify: two rows with the same x,y and different z",
        heightmap("0,0,1\n1,0,1\n0,1,1\n1,1,1\n0,0,3\n"),
        V,
        2,
        "give x=0, y=0 two heights",
    ),
    Case(
        "a program 500 mm below the part",
        lambda w: (w / "prog.gcode").write_text(
            "G21 G90\nG0 Z30\nG0 X5 Y5\nG1 Z-500 F200\nG1 X15 Y15\nG0 Z30\nM2\n"
        ),
        ("verify", "{gcode}", "--against", "{map}", "--cutter", "ball6", "--png", "{work}/verify.png"),
        1,
        "prog.gcode: cuts 50",
    ),
    Case(
        "levels that contradict the frames (17 and 7 mm swapped)",
        scan_json(lambda d: (d["frames"][1].update(level_mm=7.0), d["frames"][6].update(level_mm=17.0))),
        P,
        2,
        # each frame is read beside the two below it (monotone exposure), so the swapped frames
        # leave no confirmed part at 11 mm: the first contradiction seen from the top
        "level 11 mm: no part visible although higher levels showed it: the part left the view, "
        "a frame failed, or the frames contradict their levels",
    ),
    Case(
        "a frame symlinked outside the scan folder",
        symlink_frame_outside,
        P,
        2,
        "0003.png: is a link to a file outside the scan folder",
    ),
    # -- more of our own: scan.json ------------------------------------------------------------
    Case(
        "nested 100 deep inside an unknown key",
        deep_inside(100),
        P,
        2,
        "nests objects or lists deeper than 32",
    ),
    Case(
        "a 5000-digit number",
        raw_scan_json('{"camera": {"width": ' + "9" * 5000 + "}}"),
        P,
        2,
        "scan.json: not valid JSON",
    ),
    Case("scan.json not UTF-8", raw_scan_json(b'{"format": "\xff\xfe"}'), P, 2, "scan.json: not valid JSON"),
    Case("scan.json of 17 MB", raw_scan_json(" " * (17 * 1024**2) + "{}"), P, 2, "a scan.json is at most"),
    Case("scan.json a list", raw_scan_json("[1, 2]"), P, 2, "top level must be an object"),
    Case("width a float", camera(width=240.0), P, 2, "camera.width/height must be positive integers"),
    Case("homography all zeros", camera(homography=[[0] * 3] * 3), P, 2, "camera.homography is all zeros"),
    Case(
        "homography of rank 2",
        camera(homography=[[0.25, 0.25, 0], [0.5, 0.5, 0], [0, 0, 1]]),
        P,
        2,
        "camera.homography is singular",
    ),
    Case(
        "homography of 1e-9 mm per pixel",
        camera(homography=[[1e-9, 0, 0], [0, 1e-9, 0], [0, 0, 1]]),
        P,
        2,
        "mm per pixel",
    ),
    Case(
        "homography as a string",
        camera(homography="identity"),
        P,
        2,
        "camera.homography is not a matrix of numbers",
    ),
    Case(
        "K with a principal point far outside",
        lens(K=[[1000, 0, 1e6], [0, 1000, 120], [0, 0, 1]]),
        P,
        2,
        "principal point",
    ),
    Case(
        "K with a last row not 0 0 1",
        lens(K=[[1000, 0, 120], [0, 1000, 120], [1, 0, 1]]),
        P,
        2,
        "camera.K must have the form",
    ),
    Case(
        "K with a focal length of 1e12 px",
        lens(K=[[1e12, 0, 120], [0, 1e12, 120], [0, 0, 1]]),
        P,
        2,
        "is no lens for a 240x240 image",
    ),
    Case("dist that folds the frame back", lens(dist=FOLDING_LENS), P, 2, "camera.dist is not a lens"),
    Case("dist as a string", lens(dist="barrel"), P, 2, "camera.dist must be 4, 5, 8, 12 or 14"),
    Case(
        "a level at NaN",
        raw_scan_json(
            '{"camera": {"width": 240, "height": 240, "homography": '
            + json.dumps(CONE_H)
            + '}, "frames": [{"file": "frames/0001.png", '
            '"level_mm": NaN}]}'
        ),
        P,
        2,
        "frames[0].level_mm is not finite",
    ),
    Case(
        "a level above level_at_home_mm",
        both(scan_json(lambda d: d.update(level_at_home_mm=18.0))),
        P,
        2,
        "frames[0].level_mm is 19 mm: beyond the stage's travel (the liquid is at most 18 mm",
    ),
    Case(
        "level_at_home_mm negative",
        scan_json(lambda d: d.update(level_at_home_mm=-5)),
        P,
        2,
        "level_at_home_mm is -5",
    ),
    Case(
        "a tank area of 1e300",
        scan_json(lambda d: d.update(tank={"inner_area_mm2": 1e300})),
        P,
        2,
        "tank.inner_area_mm2 is 1e+300",
    ),
    Case(
        "a tank without its area",
        scan_json(lambda d: d.update(tank={})),
        P,
        2,
        "tank.inner_area_mm2 is missing",
    ),
    Case(
        "meniscus as a string",
        scan_json(lambda d: d.update(meniscus="water")),
        P,
        2,
        "meniscus must be an object",
    ),
    Case(
        "meniscus contact angle of 500 deg",
        scan_json(lambda d: d.update(meniscus={"capillary_length_mm": 2.7, "contact_angle_deg": 500})),
        P,
        2,
        "impossible meniscus",
    ),
    Case(
        "calibration entry as a list",
        scan_json(lambda d: d.update(calibration={"tank": [1]})),
        P,
        2,
        "calibration.tank must be an object",
    ),
    Case(
        "calibration date as a string",
        scan_json(lambda d: d.update(calibration={"camera": {"date": "today"}})),
        P,
        2,
        "calibration.camera.date is not a number",
    ),
    Case(
        "a frame file given as an object",
        scan_json(lambda d: d["frames"][1].update(file={"a": 1})),
        P,
        2,
        "frames[1].file must be a file name",
    ),
    Case(
        "a frame listed twice",
        scan_json(lambda d: d["frames"].append({"file": "frames/0001.png", "level_mm": 3.0})),
        P,
        2,
        "lists frames/0001.png a second time",
    ),
    Case(
        "a frame's target_mm a string",
        scan_json(lambda d: d["frames"][0].update(target_mm="top")),
        P,
        2,
        "frames[0].target_mm is not a number",
    ),
    Case(
        "20 000 frames",
        scan_json(
            lambda d: d.update(
                frames=[{"file": f"frames/{i}.png", "level_mm": i * 0.01} for i in range(20000)]
            )
        ),
        P,
        2,
        "20000 frames; a scan has at most",
    ),
    Case(
        "the frames folder symlinked outside", symlink_frames_folder_outside, P, 2, "outside the scan folder"
    ),
    Case(
        "scan.json symlinked outside",
        symlink_scan_json_outside,
        P,
        2,
        "scan.json: is a link to a file outside",
    ),
    Case("a 16-bit frame", frame_16_bit, P, 2, "0003.png: frame must be 8-bit"),
    Case("a frame that is a folder", frame_is_a_folder, P, 2, "0003.png: is not a plain file"),
    Case(
        "a meniscus file with a negative capillary length",
        lambda w: (w / "men.json").write_text('{"capillary_length_mm": -3, "contact_angle_deg": 10}'),
        P + ("--meniscus", "{work}/men.json"),
        2,
        "impossible meniscus",
    ),
    Case("OUT inside a file", None, ("process", "{scan}", "-o", "{map}/out"), 2, "is not a folder"),
    # -- more of our own: height maps, programs and their outputs ----------------------------
    Case(
        "a lattice of 10^12 cells",
        heightmap("0,0,1\n0.001,0,1\n0.002,0,1\n1000,0,1\n0,0.001,1\n0,0.002,1\n0,1000,1\n"),
        T,
        2,
        "lattice of",
    ),
    Case(
        "a height of 1e300", heightmap("0,0,1\n1,0,1e300\n0,1,1\n1,1,1\n"), V, 2, "has a coordinate of 1e+300"
    ),
    Case(
        "toolpath at a resolution of 1e-5 mm",
        None,
        T + ("--resolution", "1e-5"),
        2,
        "resolution: 1e-05 mm over a 20.0 x 20.0 mm part",
    ),
    Case(
        "verify at a resolution of 1e-5 mm",
        None,
        V + ("--resolution", "1e-5"),
        2,
        "resolution: 1e-05 mm over a 20.0 x 20.0 mm part",
    ),
    Case("toolpath -o a folder", None, ("toolpath", "{map}", "-o", "{out}"), 2, "is a folder"),
    Case(
        "toolpath -o in a missing folder",
        None,
        ("toolpath", "{map}", "-o", "{work}/nope/t.gcode"),
        2,
        "nope is not a folder",
    ),
    Case(
        "toolpath -o on a read-only file system",
        None,
        ("toolpath", "{map}", "-o", "{ro}/t.gcode"),
        2,
        "cannot be written",
    ),
    Case(
        "toolpath --rough-out on a read-only file system",
        None,
        T + ("--rough-out", "{ro}/r.gcode"),
        2,
        "cannot be written",
    ),
    Case("verify --png on a read-only file system", None, V[:-1] + ("{ro}/v.png",), 2, "cannot be written"),
    Case("verify --max-gouge -1", None, V + ("--max-gouge", "-1"), 2, "--max-gouge: must be >= 0"),
]


def _argv(case, w, ro):
    fill = dict(scan=w / "scan", out=w / "out", map=w / "map.csv", gcode=w / "prog.gcode", work=w, ro=ro)
    return [str(a).format(**fill) for a in case.argv]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hostile_input_is_one_line_and_keeps_the_outputs(case, work, capsys):
    ro = read_only_folder(work)
    if "{ro}" in " ".join(case.argv) and ro is None:
        pytest.skip("no read-only folder here (root, and /proc/sys writable)")
    if case.build:
        case.build(work)
    out = work / "out"
    before = folder_hash(out) if out.is_dir() else out.read_bytes()
    argv = _argv(case, work, ro)
    capsys.readouterr()
    TRIED.append(case.name)
    try:
        code = main(argv)
    except SystemExit as e:  # argparse: not what these cases are about
        pytest.fail(f"argparse refused {argv}: exit {e.code}")
    except BaseException:
        pytest.fail(f"Traceback instead of one line:\n{traceback.format_exc()}")
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert code == case.code, f"exit {code}, expected {case.code}; stderr: {err}"
    assert len(lines) == 1 and lines[0].startswith("inkslice: error: "), err
    assert case.says in lines[0], lines[0]
    assert "Traceback" not in err
    after = folder_hash(out) if out.is_dir() else out.read_bytes()
    assert after == before, "the output folder changed"


def test_a_full_disk_while_writing_the_outputs_is_one_line_and_keeps_the_old_set(work):
    # issue 19: a full disk left 2 of 6 outputs new and 4 old, after a traceback. The real
    # `inkslice` in a child whose files may not grow past 20 kB (RLIMIT_FSIZE: a disk that
    # fills during the writing); the seed method, to be quick
    import resource
    import signal
    import subprocess
    import sys

    def small_disk():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    before = folder_hash(work / "out")
    TRIED.append("OUT on a full disk")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "appliance.cli",
            "process",
            str(work / "scan"),
            "-o",
            str(work / "out"),
            "--pipeline",
            "seed",
        ],
        preexec_fn=small_disk,
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
        timeout=300,
    )
    lines = r.stderr.splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and lines[0].startswith("inkslice: error: ") and "File too large" in lines[0], (
        r.stderr
    )
    assert folder_hash(work / "out") == before
    assert [p.name for p in work.iterdir() if p.name.startswith(".inkslice-")] == []


# -- what must still be accepted -------------------------------------------------------------


@pytest.mark.parametrize("scale", [1e-5, 1e5, -1.0])
def test_a_homography_is_judged_whatever_its_scale(valid, tmp_path, scale):
    # a homography and any multiple of it are one mapping: once refused as "singular" at 1e-5
    from appliance.scanfile import load_scan

    shutil.copytree(valid / "scan", tmp_path / "scan")
    camera(homography=(np.array(CONE_H) * scale).tolist())(tmp_path)
    scaled = load_scan(tmp_path / "scan")
    plain = load_scan(valid / "scan")
    uv = np.array([[0.0, 0.0], [239.0, 17.5], [120.0, 239.0]])
    assert np.allclose(scaled.camera.pixels_to_mm(uv), plain.camera.pixels_to_mm(uv))


def test_real_cameras_and_the_edges_of_the_ranges_are_accepted(valid, tmp_path):
    from appliance.scanfile import check_frames, load_scan
    from appliance.sim.rig import Rig

    shutil.copytree(valid / "scan", tmp_path / "rig" / "scan")
    shutil.copytree(valid / "scan", tmp_path / "scan")
    # the simulated bench's camera: a real K, lens distortion, a tilted homography
    rig_cam = Rig().camera_model().to_json()
    assert load_scan_with(tmp_path / "rig", lambda d: d.update(camera=rig_cam)).camera.K is not None

    def edge_levels(d):
        d.update(level_at_home_mm=19.0, tank={"inner_area_mm2": 22500.0})
        d["frames"][-1]["level_mm"] = 0.0  # the base top itself, and the level at home

    scan = load_scan_with(tmp_path, edge_levels)
    check_frames(scan)
    assert [f.level_mm for f in scan.frames][::7] == [19.0, 0.0]
    assert load_scan(tmp_path / "scan").extra["tank"] == {"inner_area_mm2": 22500.0}


def load_scan_with(w, edit):
    from appliance.scanfile import load_scan

    scan_json(edit)(w)
    return load_scan(w / "scan")


def test_repeated_rows_with_the_same_height_are_one_point(tmp_path):
    from appliance.outputs import read_heightmap_csv

    (tmp_path / "m.csv").write_text("x,y,z\n0,0,1\n1,0,2\n0,1,3\n1,1,4\n0,0,1\n")
    hm = read_heightmap_csv(tmp_path / "m.csv")
    assert hm.z.tolist() == [[1, 2], [3, 4]]


def test_verify_passes_a_program_that_stays_clear_of_the_part(work, capsys):
    argv = _argv(Case("", None, V, 0, ""), work, None)
    assert main(argv) == 0, capsys.readouterr().err
    assert "gouge" in capsys.readouterr().out


@pytest.mark.parametrize(
    "key, value, says",
    [
        ("min_free_mb", 0, "must be at least 50"),
        ("steep_angle_deg", 1e308, "at most 85"),
        ("envelope_z_mm", 0, "at least 1"),
        ("envelope_z_mm", 1e9, "at most 10000"),
        ("adaptive_change", 2.0, "at most 1"),
        ("settle_s", 1e6, "at most 600"),
        ("cutter_diameter_mm", 1e-9, "at least 0.1"),
        ("level_at_home_mm", float("inf"), "must be a number"),
    ],
)
def test_settings_out_of_range_are_refused(key, value, says):
    from appliance.daemon import settings as S
    from appliance.errors import SettingError

    with pytest.raises(SettingError) as e:
        S.validate(S.DEFAULTS, {key: value})
    assert e.value.where == key and says in e.value.problem


def test_every_default_setting_is_inside_its_range():
    from appliance.daemon import settings as S

    assert S.validate(S.DEFAULTS, {}) == S.DEFAULTS


def test_the_suite_says_how_many_cases_it_tried(capsys):
    with capsys.disabled():
        print(f"\nhostile inputs: {len(TRIED)} of {len(CASES) + 1} cases tried through the CLI")
    assert len(CASES) >= 60
    assert len({c.name for c in CASES}) == len(CASES)
