"""Zig-zag finishing: cutter-compensated passes over the part, scallop held.

A pass is a straight line of tool positions at spacing `resolution` (0.1 mm)
along the direction `angle` (0 = along X, 90 = along Y, anything between);
its tip heights come from the drop-cutter, so the cutter touches the design
surface (plus `leave`) and never cuts into it. Passes alternate direction.

Stepover
--------
Either fixed (`stepover`), or chosen pass by pass so the scallop is the
requested height (`scallop`, default 0.01 mm): passplan.py places the
passes, measuring each candidate's actual scallop (cusps.py, envelope.py),
above the same opening the verification measures from (opening.py).

Boundary
--------
Tool positions are kept where the axis lies within `margin` of the footprint.
Off the part the surface is the base top, so the cutter rolls down over the
edge onto it and never below it (the drop-cutter holds it on the edge and
the base). With margin RIM (the cutter's radius less a tenth of a step; a ball's less
a whole step where no face at the outline is steeper than its side there, see
finishing(); the positions close up a little so both ends of a pass reach it) the
passes run off the outline until the cutter has all but left the part, so the rim is finished
like the rest; where a pass rolls over the outline its tips come from fine
lines (rimline.py). RIM is the default. With margin 0 (1.1-1.3x faster on
sample 1, see benches/cam.py) the axis never leaves the part, and the strip
the cutter could only reach from outside stays uncut. A pass broken by a hole or a bay of the
footprint becomes several runs; the program builder retracts between them.

Neighbouring runs that end and start within two stepovers are linked by a
move that follows the surface (dropped like the passes), so the cutter stays
down between passes instead of retracting 200 times (linking.py). Every
move is refined where it would cut in and thinned to the chord tolerance
(polyline.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from ..errors import SettingError, check_mm
from ..forks import in_parts, joined
from .bands import plan_in_bands
from .contact import drop_lines
from .cutters import Cutter
from .dropcutter import DEFAULT_RESOLUTION
from .linking import links
from .polyline import reduce_polyline, refine, refine_tolerance, true_runs
from .rimline import FineEnds
from .sampling import Sampler

DEFAULT_SCALLOP = 0.01  # mm
DEFAULT_CHORD = 0.002  # mm
RIM = float("inf")  # margin: run off the outline by the cutter's radius


@dataclass
class FinishSettings:
    cutter: Cutter
    scallop: float | None = DEFAULT_SCALLOP
    stepover: float | None = None
    angle: float = 0.0
    resolution: float = DEFAULT_RESOLUTION
    chord: float | None = None
    # RIM (the cutter's radius less a tenth of a step) finishes the rim, at 1.1-1.3x the CPU of
    # margin 0 on sample 1 (benches/cam.py); margin 0 leaves the strip only reachable from
    # outside the outline uncut (the acceptance table's 0.11-0.55 mm at sample edges)
    margin: float = RIM
    leave: float = 0.0
    rim: bool = field(default=False, init=False, repr=False)  # margin was RIM

    def __post_init__(self):
        if self.margin == RIM:
            # a tenth of a step short of a radius: at a full radius the cutter meets the
            # outline with its rim, where a ball's tip moves ~100x faster than its place and
            # the 0.0001 mm of a G-code coordinate was 0.007 mm of gouge at sample 1's
            # corner (at a tenth short ~12x: 0.0006). A whole step short was too short: a
            # flat end's bottom reaches a cell at the outline only from within R of it (the
            # slope times the step was left at sample 3's corner, 0.0643 where 0.05 was
            # asked), and the side of a ball or a bull nose's corner at the outline was not
            # as steep as the face beside it, which the verification reaches from further
            # out: along sample 4's 80-degree faces' edge a 1 mm ball's side was 74 degrees
            # (0.0371 left where 0.01 was asked, 0.0109 at a tenth), a bull nose r0.25's 67
            # (0.057, 0.0102 at a tenth). finishing() takes a ball back to a whole step
            # short where the outline's faces are gentler than its side there
            self.margin = max(self.cutter.radius - self.resolution / 10, 0.0)
            self.rim = True
        if self.chord is None:
            # a straight move may stand this far above the tips it replaces, which
            # adds directly to the scallop: keep it a twentieth of the request
            h = self.scallop if self.stepover is None and self.scallop else DEFAULT_SCALLOP
            self.chord = min(DEFAULT_CHORD, h / 20) if np.isfinite(h) and h > 0 else DEFAULT_CHORD

    def check(self):
        R = self.cutter.radius
        if self.stepover is not None:
            check_mm("stepover", self.stepover)
            if self.stepover >= self.cutter.diameter:
                raise SettingError(
                    "stepover",
                    f"{self.stepover:g} mm is not less than the cutter "
                    f"diameter {self.cutter.diameter:g} mm: strips would be left uncut",
                )
        else:
            check_mm("scallop", self.scallop)
            if self.scallop >= R:
                raise SettingError(
                    "scallop", f"{self.scallop:g} mm is not less than the cutter radius {R:g} mm"
                )
        check_mm("resolution", self.resolution)
        if not np.isfinite(self.angle):
            raise SettingError("angle", f"must be a number of degrees, got {self.angle}")
        if self.resolution > R / 3:
            raise SettingError(
                "resolution",
                f"{self.resolution:g} mm is too coarse for a cutter of radius "
                f"{R:g} mm (at most {R / 3:.3g} mm)",
            )
        check_mm("chord tolerance", self.chord)
        check_mm("margin", self.margin, zero_ok=True)
        if self.margin > R:
            raise SettingError(
                "margin",
                f"{self.margin:g} mm is more than the cutter radius {R:g} mm: "
                "the cutter would drop off the part's edge to the base",
            )
        check_mm("stock to leave", self.leave, zero_ok=True)


@dataclass
class Finish:
    runs: list  # list of (k, 3) arrays of tool-tip positions, cutting order
    linked: list  # linked[i]: run i is joined to run i-1 without a retract
    passes: np.ndarray  # across-position of every pass (mm)
    stepovers: np.ndarray
    margin: float  # how far the axis went past the outline (mm)


def check_fits(sampler: Sampler, cutter: Cutter):
    x0, x1, y0, y1 = sampler.bounds
    w = min(x1 - x0, y1 - y0)
    if cutter.diameter > w:
        raise SettingError(
            "cutter",
            f"diameter {cutter.diameter:g} mm is larger than the part "
            f"({x1 - x0:.1f} x {y1 - y0:.1f} mm): choose a smaller cutter",
        )


def pass_frame(sampler: Sampler, angle_deg, margin):
    th = np.radians(angle_deg)
    e1 = np.array([np.cos(th), np.sin(th)])
    e2 = np.array([-e1[1], e1[0]])
    (t0, t1), (s0, s1) = sampler.footprint_extent(e1), sampler.footprint_extent(e2)
    return e1, e2, (t0 - margin, t1 + margin), (s0 - margin, s1 + margin)


def finishing(sampler: Sampler, st: FinishSettings) -> Finish:
    """Passes over the part; give `sampler` an edge_step (resolution / 2) so edges are contacts."""
    st.check()
    check_fits(sampler, st.cutter)
    step_short = st.cutter.radius - st.resolution
    if (
        st.rim
        and st.cutter.kind == "ball"
        and step_short > 0
        and not steep_outline(sampler, st.cutter.radius, step_short)
    ):
        # a step short reaches every face at the outline, and keeps the positions on the
        # lattice's phase: a tenth short on sample 1's dome put them 0.01 mm off it, where the
        # drop's lattice error (~0.0004 mm) made 2400 moves at its top look bent to refine()
        # (3 -> 8 levels of scattered drops, ~6 % of the program's time)
        st = replace(st, margin=step_short)
    e1, e2, (t0, t1), (s0, s1) = pass_frame(sampler, st.angle, st.margin)
    short = (t1 - t0) - np.floor((t1 - t0) / st.resolution + 1e-9) * st.resolution
    if st.margin > 0 and short > st.resolution / 20:
        # positions a little closer than `resolution`, so the last one of a pass is on the
        # margin as the first is: on whole steps they stopped up to a step short at the far
        # end (flat6 on sample 3: 0.0631 left at x = 100, its last positions 2.91 mm out)
        st = replace(st, resolution=(t1 - t0) / np.ceil((t1 - t0) / st.resolution))
    d = st.resolution
    n = int(np.ceil((t1 - t0) / d - 1e-9)) + 1
    origin = lambda s: t0 * e1 + s * e2
    drop_cutter = st.cutter.offset(st.leave) if st.leave > 0 else st.cutter
    planned = None
    if st.stepover is not None:
        k = int(np.ceil((s1 - s0) / st.stepover - 1e-9))
        passes = np.linspace(s0, s1, k + 1) if k > 0 else np.array([s0])
    else:
        passes, planned = plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1)
    origins = np.array([origin(s) for s in passes])
    if planned is not None and st.leave == 0:
        # the planner dropped the cutter along every pass it placed (inf off the part,
        # where no position is kept): the same tips, not a second drop
        tips = planned
    else:
        tips = drop_lines(sampler, drop_cutter, origins, e1, n, d) + st.leave
    # tips half-way between points, to catch where the tip height is concave
    # (the cutter rolling over an edge) and a straight move would cut in; this and the
    # refinement below are the serial tail after the planning: in halves on the cores
    half_way = origins + 0.5 * d * e1[None, :]
    mids = in_parts(
        lambda a, b: drop_lines(sampler, drop_cutter, half_way[a:b], e1, n - 1, d),
        np.ones(len(passes)),
        np.concatenate,
    )
    mids += st.leave
    along = t0 + d * np.arange(n)
    tol = refine_tolerance(st.chord)
    out = sampler.part_distance(
        along[None, :] * e1[0] + passes[:, None] * e2[0], along[None, :] * e1[1] + passes[:, None] * e2[1]
    )
    within = out <= st.margin + 1e-9
    fine = FineEnds(sampler, drop_cutter, origins, e1, d, tips, mids, within, out > 0, tol, st.leave)
    ordered = []
    for k, s in enumerate(passes):
        pts = along[:, None] * e1[None, :] + s * e2[None, :]
        xyz = np.column_stack([pts, tips[k]])
        mid = np.column_stack([(along[:-1] + 0.5 * d)[:, None] * e1[None, :] + s * e2[None, :], mids[k]])
        pass_runs = [fine.insert(k, xyz[a:b], mid[a : b - 1], a) for a, b in true_runs(within[k])]
        if k % 2 == 1:
            pass_runs = [(r[::-1], len(r) - 2 - c) for r, c in pass_runs[::-1]]
        ordered.extend(pass_runs)
    moves, cand = [r for r, _ in ordered], [np.sort(c) for _, c in ordered]
    ordered = in_parts(
        lambda a, b: refine(sampler, drop_cutter, moves[a:b], tol, st.leave, d, cand=cand[a:b]),
        [c.size + len(r) / 100 for r, c in zip(moves, cand)],
        joined,
    )
    joins = links(sampler, drop_cutter, st, ordered, passes)
    runs: list[np.ndarray] = []
    keeps: list[np.ndarray] = []
    linked: list[bool] = []
    for i, r in enumerate(ordered):
        kr = np.zeros(len(r), bool)
        kr[[0, -1]] = True
        if i > 0 and joins[i - 1] is not None:
            runs[-1] = np.vstack([runs[-1], joins[i - 1], r])
            keeps[-1] = np.concatenate([keeps[-1], np.ones(len(joins[i - 1]), bool), kr])
        else:
            runs.append(r)
            keeps.append(kr)
            linked.append(False)
    runs = [reduce_polyline(r, st.chord, k) for r, k in zip(runs, keeps)]
    steps = np.diff(passes) if passes.size > 1 else np.zeros(0)
    return Finish(runs, linked, passes, steps, st.margin)


def steep_outline(sampler: Sampler, radius: float, margin: float) -> bool:
    """Whether a face at the outline is steeper than the side of a ball of `radius` whose axis
    stands `margin` past it: the ball touches such a face's last strip only from further out
    (sample 4's 80-degree faces: a 1 mm ball's side at 0.48 mm out is 74 degrees)."""
    on = sampler.cell_on
    edge = on & ~ndimage.binary_erosion(np.pad(on, 1), np.ones((3, 3), bool))[1:-1, 1:-1]
    g00, g10, g01, g11 = (g[edge] for g in sampler.corner_grids)
    # the cell's two triangles' gradients (sampling.py splits it from (i, j) to (i+1, j+1))
    upper = np.hypot((g10 - g00) / sampler.dx, (g11 - g10) / sampler.dy)
    lower = np.hypot((g11 - g01) / sampler.dx, (g01 - g00) / sampler.dy)
    slope = float(np.max(np.maximum(upper, lower), initial=0.0))
    side = margin / np.sqrt(max(radius * radius - margin * margin, 1e-12))  # tan of the side's angle
    return slope > side
