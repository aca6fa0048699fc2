"""Waterlines read as the frames land (waterlines.py, daemon/processing_child.py --follow).

The daemon's processing child reads each frame while the scan runs, once the frames below
it that confirm it are final. Whatever order the frames came in, the result must be what
one read of the finished scan gives.
"""

import os
import threading

import numpy as np
from scan_helpers import camera
from test_vision_temporal import LEVELS, frame

from appliance.daemon.processing_child import follow, settled
from appliance.scanfile import FrameRef, Scan, load_scan, write_frame, write_scan_json
from appliance.waterlines import CONFIRMING_FRAMES, TopDownReader, extract_waterlines, waterline_frames

BLOBS = (17, 13, 11)  # glare the lower frames must veto: the reading depends on them


def _add(folder, refs, level, extra=None):
    rel = f"frames/{len(refs) + 1:04d}.png"
    write_frame(folder, rel, frame(level, level in BLOBS))
    refs.append(FrameRef(rel, float(level), extra or {}))
    write_scan_json(Scan(folder, camera(), refs, {}))
    return load_scan(folder)


def _same(a, b):
    assert [w.level_mm for w in a] == [w.level_mm for w in b]
    for wa, wb in zip(a, b):
        assert len(wa.loops) == len(wb.loops)
        assert all(np.array_equal(p, q) for p, q in zip(wa.loops, wb.loops))


def test_read_as_the_frames_land_is_one_read_of_the_finished_scan(tmp_path):
    refs, reader = [], None
    for level in LEVELS:
        scan = _add(tmp_path, refs, level)
        reader = reader or TopDownReader(scan)
        frames = waterline_frames(scan)
        got = reader.read(frames)
        # a frame is read only once the frames that confirm it are there
        assert len(got) == max(0, len(frames) - CONFIRMING_FRAMES)
    _same(reader.finish(scan), extract_waterlines(scan))


def test_a_frame_that_comes_in_above_what_was_read_starts_the_reading_again(tmp_path):
    refs = []
    for level in LEVELS[:6]:
        scan = _add(tmp_path, refs, level)
    reader = TopDownReader(scan)
    assert len(reader.read(waterline_frames(scan))) == 4  # 19 .. 13 read
    # the runner went back into the step 17 -> 15 to refine it
    scan = _add(tmp_path, refs, 16, {"refines": [17, 15]})
    for level in LEVELS[6:]:
        scan = _add(tmp_path, refs, level)
    finished = reader.finish(scan)
    assert [w.level_mm for w in finished] == sorted((*LEVELS, 16), reverse=True)
    _same(finished, extract_waterlines(scan))


def test_settled_frames_are_those_at_or_above_the_last_steps_upper_level(tmp_path):
    refs = []
    for level in (19, 17, 15):
        scan = _add(tmp_path, refs, level)
    # the step 17 -> 15 may still be refined: 15 and what may come in above it are not settled
    assert [f.level_mm for f in settled(scan)] == [19, 17]
    scan = _add(tmp_path, refs, 16, {"refines": [17, 15]})
    assert [f.level_mm for f in settled(scan)] == [19, 17]
    scan = _add(tmp_path, refs, 13)
    assert [f.level_mm for f in settled(scan)] == [19, 17, 16, 15]
    assert settled(load_scan(tmp_path)) == settled(scan)


def _piped():
    r, w = os.pipe()
    return os.fdopen(r, "r"), os.fdopen(w, "w")


def test_a_following_child_reads_until_go_and_leaves_when_stdin_closes_first(tmp_path):
    refs = []
    for level in LEVELS:
        _add(tmp_path, refs, level)
    stdin, to_child = _piped()
    out = {}
    t = threading.Thread(target=lambda: out.update(r=follow(tmp_path, stdin)))
    t.start()
    to_child.write("go\n")
    to_child.flush()
    t.join(timeout=60)
    go, reader = out["r"]
    assert go and reader is not None
    _same(reader.finish(load_scan(tmp_path)), extract_waterlines(load_scan(tmp_path)))

    stdin, to_child = _piped()
    to_child.close()  # the scan failed before its capture was over
    assert follow(tmp_path, stdin) == (False, None)
