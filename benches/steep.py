"""Steep walls and tool changes (issue 20): figures for the acceptance rows.

    .venv/bin/python benches/steep.py            # both (~5-10 min on 2 busy cores)
    .venv/bin/python benches/steep.py --only walls|tools

walls: a round mesa 8 mm high whose wall slope goes round from 60 to 85
degrees (a logistic profile, so the top edge and the foot are rounded, not
knife edges the drop-cutter's lattice would straddle), on a 40 x 40 mm floor,
from a 0.2 mm height map. Finished with a 6 mm ball at scallop 0.05 mm two
ways: steep and shallow (waterline.py, threshold 50 deg) and zig-zag alone
(zigzag.py, the planner holding the scallop pass by pass). `inkslice verify`'s
simulation measures both; the wall band is the measured cells whose design
slope is 55 deg or more. The scallop is vertical, as verify measures it.

tools: the three-tool job (T1 flat6 roughing, T2 ball6 steep-and-shallow
finishing, T3 ball2 rest) on the same part: each dialect through rs274 and our
rule checkers, and the material the whole job leaves against the finishing
tool alone.

Measured (2026-12-03, this machine under a load of ~8-10, CPU seconds). Before:
the code before the drop-cutter met steep faces exactly (3ab8bb7), run at 05:10;
after: at 05:31-05:45, same box, same load:

    strategy            CPU s  lines  gouge   max sc  uncut %  wall mm2  wall max  wall p99  >1.1h %
    steep+shallow old    23.9  30072  0.0586  0.1671   4.32      97     0.1671    0.0356    0.26
    steep+shallow new    26.4  28252  0.0014  0.1502   4.40      94     0.1502    0.0334    0.31
    zig-zag alone old    15.1   7361  0.0613  0.0524   4.39      97     0.0551    0.0435    0.01
    zig-zag alone new    18.3   6841  0.0039  0.0568   4.42      94     0.0609    0.0440    0.01

    three-tool job old: planned in 31.4 s; whole job gouge 0.1065 mm, 9.46 mm^3 left, 2.3 mm^2
    uncut; finishing alone gouge 0.0586 mm, 38.16 mm^3 left, 69.5 mm^2 uncut.
    three-tool job new: planned in 33.7 s; linuxcnc, mach3, fanuc pass rs274 (fanuc our rules
    too), the three GRBL files our rules; whole job gouge 0.0024 mm, 9.88 mm^3 left, 2.8 mm^2
    uncut; finishing alone gouge 0.0014 mm, 39.19 mm^3 left, 70.8 mm^2 uncut; no rapid cuts.
    The gouge per operation (verified one at a time, 05:20, an earlier form of the fix):
    roughing 0 before and after, finishing 0.0586 -> 0.0014, rest 0.1065 -> 0.0024.

What holds and what does not. The gouge was the drop-cutter's (contact.polish):
an axis on the floor beside the wall was never polished (no slope at the axis,
while the cutter meets the wall with its side: 0.085 mm low), and its pattern
search only samples offsets, where h'' ~ 500 /mm near the rim on an 85-degree
face; now the triangles round the contact are met exactly (facet_contacts).
The scallop on the walls was not held: 99 % of the band within 0.033 mm but cells
at the foot of the 85-degree side at 0.150. Three causes, found and fixed in
waterlines() (levels.py), measured one at a time with this bench's walls row
(steep+shallow; the box at a load of 5-20, so CPU is not comparable across rows):

    change                                    levels  dz    gouge   wall max  wall p99  CPU s
    before (main 13e7e57, 07:31)                 22  0.401  0.0014   0.1502    0.0334    29.4
    + points moved onto their level (on_level)   22  0.401  0.0014   0.1320    0.0341    54.7
    + lowest level on the crease (lo + 0.01)     22  0.401  0.0232   0.0640    0.0298    70.7
    + lowest level lo + 0.04 (FOOT)              22  0.401  0.0014   0.0658    0.0291    66.6
    + dz from the steepest slope read (84.1)     24  0.350  0.0014   0.0577    0.0260    79.1
    + a degree for the lattice's reading (85.1)  27  0.320  0.0014   0.0449    0.0205    90.2

The foot: the lowest level lay below the floor (no contour), so the band of wall
between the crease (a cutter on the floor touching the wall with its side,
~2.7 mm up the 85-degree side) and the next level up kept that gap as scallop.
On the crease itself the drop-cutter's polish misses the wall behind the
floor's contact (0.026 mm low at x=22.7 y=31.8 against a brute-force drop:
the ring scan's start loses to the floor's, so the exact facets are met
around the wrong contact), hence the 0.0232 gouge: the lowest loop stands
0.04 mm above the floor instead. That drop-cutter defect was contact.polish's
(fixed 3 December, session 13: both starts' windows are met where they ended
apart; FOOT kept, not re-measured). The level step:
the 99th percentile of the tip field's slope (82 degrees) held 0.066 mm on the
85-degree side; the steepest slope read, plus the degree the 0.2 mm lattice's
differences take off an 85-degree wall, holds it at 27 levels instead of 22.
Now (this bench's own walls row, 08:40, load ~18): steep+shallow 80.7 s CPU,
33574 lines, gouge 0.0014, max 0.0473, uncut 4.39 %, wall band 94 mm^2, wall
max 0.0449 for 0.05 asked (no tolerance needed), p99 0.0205, none > 1.1h.
Zig-zag alone beside it (same run): 25.4 s, 6842 lines, gouge 0.0039, max
0.0568, wall max 0.0609, p99 0.0440 (unchanged code, as before). Three-tool
job (same run): planned in 102.6 s CPU (33.7 before, load ~5 then); linuxcnc,
mach3, fanuc pass rs274 (fanuc our rules too), the three GRBL files our rules;
whole job gouge 0.0016 mm (0.0024 before), 9.59 mm^3 left, 2.5 mm^2 uncut;
finishing alone gouge 0.0014, 38.87 mm^3, 70.6 mm^2; no crashes.
Not a waterline defect: tests' narrow 12 x 12 mesa (85 degrees all round, 3 mm
top radius) with ball6 keeps 0.36 mm at (6.0, 2.9) before and after (0.3659 ->
0.3602): the axis that would meet that wall's lower half stands off the map's
edge, and finishing does not run off the outline (the rim, issue 20 item 2). The CPU rows were taken at loads of 5 (first) to 20
(last): the plan's added cost is the 5 extra levels (+23 %) and ~11 exact drops
per loop point for on_level, not yet measured A/B.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from appliance.cam.cutters import parse_cutter
from appliance.cam.dialects import check_fanuc, check_grbl
from appliance.cam.jobs import finishing_gcode, verify_gcode
from appliance.cam.operations import Operation, parse_operations, plan_operations, post_operations
from appliance.cam.tools import Tool, default_tools
from appliance.cam.zigzag import FinishSettings
from appliance.surface.heightmap import HeightMap

SCALLOP = 0.05
WALL_BAND_DEG = 55.0
RS274 = "/usr/bin/rs274"


def walls_part(step=0.2):
    x = np.arange(0, 40 + step / 2, step)
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X - 20, Y - 20)
    phi = np.arctan2(Y - 20, X - 20)
    wall = np.radians(72.5 + 12.5 * np.sin(phi))  # 60 .. 85 degrees round the mesa
    H = 8.0
    s = H / (4 * np.tan(wall))  # logistic's steepest slope is H / 4s
    Z = 1 + H / (1 + np.exp((r - 9) / s)) + 0.8 * np.clip(1 - (r / 9) ** 2, 0, 1)
    return HeightMap(x, x, Z)


def band_figures(rep, hm):
    st = rep.deviation.shape
    xs = hm.x[0] + 0.1 * np.arange(st[1])
    ys = hm.y[0] + 0.1 * np.arange(st[0])
    from appliance.cam.sampling import Sampler

    s = Sampler(hm)
    X, Y = np.meshgrid(xs, ys)
    Z = s.z(X, Y)
    gy, gx = np.gradient(Z, 0.1)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    band = rep.measured & (slope >= WALL_BAND_DEG)
    dev = np.maximum(rep.deviation[band], 0)
    return (
        band.sum() * 0.01,
        float(dev.max()) if dev.size else float("nan"),
        float(np.percentile(dev, 99)) if dev.size else float("nan"),
        float(np.mean(dev > 1.1 * SCALLOP)) if dev.size else 0,
    )


def timed(fn):
    t = time.process_time()
    out = fn()
    return out, time.process_time() - t


def walls():
    hm = walls_part()
    print(
        f"walls part: {hm.x.size} x {hm.y.size} map at 0.2 mm, wall slope 60-85 deg, scallop {SCALLOP} mm, ball6"
    )
    print(
        f"{'strategy':<20}{'CPU s':>7}{'lines':>8}{'gouge':>8}{'max sc':>8}{'uncut %':>8}"
        f"{'wall mm2':>9}{'wall max':>9}{'wall p99':>9}{'>1.1h %':>8}"
    )
    ball = Tool(2, parse_cutter("ball6"))
    for name, fn in (
        (
            "steep+shallow",
            lambda: (
                post_operations(
                    *plan_operations(hm, [Operation("finish", ball, "steep")], scallop=SCALLOP), "linuxcnc"
                )[0].text
            ),
        ),
        ("zig-zag alone", lambda: finishing_gcode(hm, FinishSettings(ball.cutter, scallop=SCALLOP)).text),
    ):
        text, cpu = timed(fn)
        rep, _ = verify_gcode(text, hm)
        area, wmax, wp99, over = band_figures(rep, hm)
        print(
            f"{name:<20}{cpu:7.1f}{text.count(chr(10)):8d}{rep.gouge:8.4f}{rep.scallop_max:8.4f}"
            f"{100 * rep.uncut_fraction:8.2f}{area:9.0f}{wmax:9.4f}{wp99:9.4f}{100 * over:8.2f}"
        )
        for what, (x, y) in (("gouge", rep.gouge_at), ("max scallop", rep.scallop_at)):
            ang = 72.5 + 12.5 * np.sin(np.arctan2(y - 20, x - 20))
            print(
                f"{'':<20}{what} at x={x:.1f} y={y:.1f}: {np.hypot(x - 20, y - 20):.2f} mm from the axis, "
                f"where the wall is {ang:.0f} deg"
            )


def tools():
    hm = walls_part()
    ops = parse_operations("rough T1, finish T2 steep, rest T3", default_tools())
    (planned, top), cpu = timed(lambda: plan_operations(hm, ops, scallop=SCALLOP))
    print(
        f"three-tool job (rough T1 flat6, finish T2 ball6 steep, rest T3 ball2): planned in {cpu:.1f} s CPU"
    )
    tmp = Path(tempfile.mkdtemp())
    try:
        for d in ("linuxcnc", "mach3", "fanuc", "grbl"):
            posted = post_operations(planned, top, d, job="walls")
            for p in posted:
                checks = []
                if d != "grbl" and Path(RS274).exists():
                    f = tmp / "p.ngc"
                    f.write_text(p.text)
                    r = subprocess.run(
                        [RS274, "-g", str(f), str(tmp / "o.txt")],
                        capture_output=True,
                        stdin=subprocess.DEVNULL,
                        timeout=300,
                    )
                    checks.append("rs274 " + ("ok" if r.returncode == 0 else "FAILED"))
                if d == "fanuc":
                    checks.append("fanuc rules " + ("ok" if not check_fanuc(p.text) else "FAILED"))
                if d == "grbl":
                    checks.append("grbl rules " + ("ok" if not check_grbl(p.text) else "FAILED"))
                print(
                    f"  {p.name}: {p.text.count(chr(10))} lines, {p.runtime_s / 60:.1f} min, {', '.join(checks)}"
                )
        whole, _ = verify_gcode(post_operations(planned, top, "linuxcnc", job="walls")[0].text, hm)
        fin = [p for p in planned if p.op.kind == "finish"]
        alone, _ = verify_gcode(post_operations(fin, top, "linuxcnc", job="walls")[0].text, hm)
        left = lambda rep: float(np.sum(np.maximum(rep.deviation, 0)[rep.part]) * 0.01)
        for name, rep in (("whole job", whole), ("finishing alone", alone)):
            print(
                f"  {name:<16} gouge {rep.gouge:.4f} mm, material left {left(rep):8.2f} mm^3, "
                f"uncut {rep.uncut_area:6.1f} mm^2, crashes {rep.crashes}"
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", choices=("walls", "tools"))
    a = ap.parse_args()
    if a.only in (None, "walls"):
        walls()
    if a.only in (None, "tools"):
        tools()


if __name__ == "__main__":
    main()
