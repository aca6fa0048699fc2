"""Zig-zag finishing: cutter-compensated passes over the part, scallop held.

A pass is a straight line of tool positions at spacing `resolution` (0.1 mm)
along the direction `angle` (0 = along X, 90 = along Y, anything between);
its tip heights come from the drop-cutter, so the cutter touches the design
surface (plus `leave`) and never cuts into it. Passes alternate direction.

Stepover
--------
Either fixed (`stepover`), or chosen pass by pass so the scallop is the
requested height (`scallop`, default 0.01 mm). The planner does not trust the
flat-surface formula: for a candidate next pass it drops the cutter along it,
then measures the actual scallop between it and the previous pass with the
cutter swept over both passes' tool positions, on cross-section rows at most
an eighth of the step apart, every 0.3 mm along the pass (every point near its
ends), on the rows between the two passes' contacts (later passes touch beyond
the second's). It searches (secant on s^2, bracketed) for the largest
stepover whose scallop is within 90-98 % of the request, which also holds the
scallop on slopes across the passes and on curved surfaces where the formula
errs by 10-15 %. The cusp's top, between rows, comes from the quadratics
through the two passes' envelopes on the rows around it (a ball's or bull
nose's envelope is smooth there); a flat end's is swept again on finer rows.

The scallop is measured as the verification measures it, above the same
opening (opening.py: what an infinitely fine stepover leaves) where that
opening comes within the reach tolerance of the design: stock no stepover
would remove is left out (a concave region tighter than the cutter, the wall
of a step, the strip downhill of the first pass). A ball's columns where
either pass touches nothing are left out too.

Boundary
--------
Tool positions are kept where the axis lies within `margin` of the footprint
(0: the axis never leaves the part; the cutter's flank finishes the edge).
Off the part the surface is the base top, so a larger margin lets the cutter
roll down over the edge. A pass broken by a hole or a bay of the footprint
becomes several runs; the program builder retracts between them.

Neighbouring runs that end and start within two stepovers are linked by a
move that follows the surface (dropped like the passes), so the cutter stays
down between passes instead of retracting 200 times.

Point reduction
---------------
Each run is thinned with Ramer-Douglas-Peucker to the chord tolerance:
collinear points disappear, and no dropped point is further than the
tolerance from the move that replaces it (vertically, or sideways at links).
A move above the tips it replaces adds to the scallop, one below them cuts
in: the default tolerance is 0.002 mm or a twentieth of the requested
scallop, whichever is smaller (0.0005 mm for the default 0.01 mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..errors import SettingError
from .contact import polish
from .cutters import Cutter
from .dropcutter import DEFAULT_RESOLUTION
from .dropcutter import drop_lines as _lattice_lines
from .opening import Opening


def drop_lines(sampler, cutter, origins, direction, n, d=DEFAULT_RESOLUTION):
    """The lattice drop-cutter, polished on steep faces (contact.py) so a tip is never
    low by the lattice's h'' d^2 / 8 there: a low tip is a gouge."""
    origins = np.atleast_2d(np.asarray(origins, float))
    e1 = np.asarray(direction, float)
    e1 = e1 / np.hypot(*e1)
    tip = _lattice_lines(sampler, cutter, origins, e1, n, d)
    t = d * np.arange(n)
    x = origins[:, :1] + t[None, :] * e1[0]
    y = origins[:, 1:2] + t[None, :] * e1[1]
    return polish(sampler, cutter, x, y, tip, d)


def drop_points(sampler, cutter, x, y, d=DEFAULT_RESOLUTION):
    x = np.asarray(x, float).ravel()
    y = np.asarray(y, float).ravel()
    return drop_lines(sampler, cutter, np.column_stack([x, y]), (1.0, 0.0), 1, d)[:, 0]


from .sampling import Sampler
from .scallop import ball_stepover, flat_stepover
from .segments import min_over_segment

DEFAULT_SCALLOP = 0.01  # mm
DEFAULT_CHORD = 0.002  # mm
PLAN_SPACING = 0.3  # mm between the points the planner measures along a pass
_ROW = 0.05  # mm between the rows of the planner's cross-sections
_BALL_ROW = 0.1  # for a ball: its envelope is a circle across the cusp, which the
# quadratic through three rows 0.1 apart gives within 1e-5 mm
_CROSS = 15  # cross-sections measured between two passes


@dataclass
class FinishSettings:
    cutter: Cutter
    scallop: float | None = DEFAULT_SCALLOP
    stepover: float | None = None
    angle: float = 0.0
    resolution: float = DEFAULT_RESOLUTION
    chord: float | None = None
    margin: float = 0.0
    leave: float = 0.0

    def __post_init__(self):
        if self.chord is None:
            # a straight move may stand this far above the tips it replaces, which
            # adds directly to the scallop: keep it a twentieth of the request
            h = self.scallop if self.stepover is None and self.scallop else DEFAULT_SCALLOP
            self.chord = min(DEFAULT_CHORD, h / 20) if np.isfinite(h) and h > 0 else DEFAULT_CHORD

    def check(self):
        R = self.cutter.radius
        if self.stepover is not None:
            if not np.isfinite(self.stepover) or self.stepover <= 0:
                raise SettingError("stepover", f"must be > 0 mm, got {self.stepover}")
            if self.stepover >= self.cutter.diameter:
                raise SettingError(
                    "stepover",
                    f"{self.stepover:g} mm is not less than the cutter "
                    f"diameter {self.cutter.diameter:g} mm: strips would be left uncut",
                )
        else:
            if self.scallop is None or not np.isfinite(self.scallop) or self.scallop <= 0:
                raise SettingError("scallop", f"must be > 0 mm, got {self.scallop}")
            if self.scallop >= R:
                raise SettingError(
                    "scallop", f"{self.scallop:g} mm is not less than the cutter radius {R:g} mm"
                )
        if not np.isfinite(self.resolution) or self.resolution <= 0:
            raise SettingError("resolution", f"must be > 0 mm, got {self.resolution}")
        if not np.isfinite(self.angle):
            raise SettingError("angle", f"must be a number of degrees, got {self.angle}")
        if self.resolution > R / 3:
            raise SettingError(
                "resolution",
                f"{self.resolution:g} mm is too coarse for a cutter of radius "
                f"{R:g} mm (at most {R / 3:.3g} mm)",
            )
        if not np.isfinite(self.chord) or self.chord <= 0:
            raise SettingError("chord tolerance", f"must be > 0 mm, got {self.chord}")
        if not np.isfinite(self.margin) or self.margin < 0:
            raise SettingError("margin", f"must be >= 0 mm, got {self.margin}")
        if self.margin > R:
            raise SettingError(
                "margin",
                f"{self.margin:g} mm is more than the cutter radius {R:g} mm: "
                "the cutter would drop off the part's edge to the base",
            )
        if not np.isfinite(self.leave) or self.leave < 0:
            raise SettingError("stock to leave", f"must be >= 0 mm, got {self.leave}")


@dataclass
class Finish:
    runs: list  # list of (k, 3) arrays of tool-tip positions, cutting order
    linked: list  # linked[i]: run i is joined to run i-1 without a retract
    passes: np.ndarray  # across-position of every pass (mm)
    stepovers: np.ndarray


def check_fits(sampler: Sampler, cutter: Cutter):
    x0, x1, y0, y1 = sampler.bounds
    w = min(x1 - x0, y1 - y0)
    if cutter.diameter > w:
        raise SettingError(
            "cutter",
            f"diameter {cutter.diameter:g} mm is larger than the part "
            f"({x1 - x0:.1f} x {y1 - y0:.1f} mm): choose a smaller cutter",
        )


def _frame(sampler: Sampler, angle_deg, margin):
    th = np.radians(angle_deg)
    e1 = np.array([np.cos(th), np.sin(th)])
    e2 = np.array([-e1[1], e1[0]])
    jj, ii = np.nonzero(sampler.cell_on)
    # corners of every on-part cell
    cx = sampler.x0 + sampler.dx * np.concatenate([ii, ii + 1, ii, ii + 1])
    cy = sampler.y0 + sampler.dy * np.concatenate([jj, jj, jj + 1, jj + 1])
    t = cx * e1[0] + cy * e1[1]
    s = cx * e2[0] + cy * e2[1]
    return e1, e2, (t.min() - margin, t.max() + margin), (s.min() - margin, s.max() + margin)


def finishing(sampler: Sampler, st: FinishSettings) -> Finish:
    """Passes over the part; give `sampler` an edge_step (resolution / 2) so edges are contacts."""
    st.check()
    check_fits(sampler, st.cutter)
    d = st.resolution
    e1, e2, (t0, t1), (s0, s1) = _frame(sampler, st.angle, st.margin)
    n = int(np.ceil((t1 - t0) / d - 1e-9)) + 1
    origin = lambda s: t0 * e1 + s * e2
    drop_cutter = st.cutter.offset(st.leave) if st.leave > 0 else st.cutter
    planned = None
    if st.stepover is not None:
        k = int(np.ceil((s1 - s0) / st.stepover - 1e-9))
        passes = np.linspace(s0, s1, k + 1) if k > 0 else np.array([s0])
    else:
        passes, planned = _plan_passes(sampler, st, e1, e2, t0, n, s0, s1)
    origins = np.array([origin(s) for s in passes])
    if planned is not None and st.leave == 0:
        # the planner dropped the cutter along every pass it placed (inf off the part,
        # where no position is kept): the same tips, not a second drop
        tips = planned
    else:
        tips = drop_lines(sampler, drop_cutter, origins, e1, n, d) + st.leave
    # tips half-way between points, to catch where the tip height is concave
    # (the cutter rolling over an edge) and a straight move would cut in
    mids = drop_lines(sampler, drop_cutter, origins + 0.5 * d * e1[None, :], e1, n - 1, d) + st.leave
    along = t0 + d * np.arange(n)
    tol = refine_tolerance(st.chord)
    ordered = []
    for k, s in enumerate(passes):
        pts = along[:, None] * e1[None, :] + s * e2[None, :]
        keep = sampler.part_distance(pts[:, 0], pts[:, 1]) <= st.margin + 1e-9
        xyz = np.column_stack([pts, tips[k]])
        mid = np.column_stack([(along[:-1] + 0.5 * d)[:, None] * e1[None, :] + s * e2[None, :], mids[k]])
        pass_runs = [_insert_mids(xyz[a:b], mid[a : b - 1], tol) for a, b in _true_runs(keep)]
        if k % 2 == 1:
            pass_runs = [(r[::-1], len(r) - 2 - c) for r, c in pass_runs[::-1]]
        ordered.extend(pass_runs)
    ordered = refine(
        sampler, drop_cutter, [r for r, _ in ordered], tol, st.leave, d, cand=[np.sort(c) for _, c in ordered]
    )
    links = _links(sampler, drop_cutter, st, ordered, passes)
    runs, keeps, linked = [], [], []
    for i, r in enumerate(ordered):
        kr = np.zeros(len(r), bool)
        kr[[0, -1]] = True
        if i > 0 and links[i - 1] is not None:
            runs[-1] = np.vstack([runs[-1], links[i - 1], r])
            keeps[-1] = np.concatenate([keeps[-1], np.ones(len(links[i - 1]), bool), kr])
        else:
            runs.append(r)
            keeps.append(kr)
            linked.append(False)
    runs = [reduce_polyline(r, st.chord, k) for r, k in zip(runs, keeps)]
    steps = np.diff(passes) if passes.size > 1 else np.zeros(0)
    return Finish(runs, linked, passes, steps)


def refine_tolerance(chord):
    return min(chord / 4, 0.0005)


def _insert_mids(pts, mid, tol):
    """Insert the midpoints whose tip is above the straight move by more than tol."""
    """Returns the points and the segments (halves of the split ones) to check further."""
    if len(pts) < 2:
        return pts, np.zeros(0, int)
    chord = 0.5 * (pts[:-1, 2] + pts[1:, 2])
    up = np.flatnonzero(mid[:, 2] - chord > tol)
    if up.size == 0:
        return pts, np.zeros(0, int)
    first = up + np.arange(up.size)
    return np.insert(pts, up + 1, mid[up], axis=0), np.concatenate([first, first + 1])


def refine(sampler, cutter, runs, tol, leave, d, max_levels=12, cand=None):
    """Split every move whose middle the cutter must pass above the straight line.

    The drop-cutter gives exact tips at the points; between them the tool
    moves in a straight line. Where the tip height is concave (the cutter
    rolling over a convex edge or corner, or a link between passes) the
    straight move runs below the tips it passes over and would cut in. Every
    move's midpoint is dropped; where it lies more than `tol` above the
    move, the midpoint is inserted and both halves are checked again. All
    runs are refined together, one drop_points call per level.
    """
    runs = [np.asarray(r, float) for r in runs]
    # candidates: (run index, segment index); start with every segment
    if cand is None:
        cand = [np.arange(max(len(r) - 1, 0)) for r in runs]
    for _ in range(max_levels):
        which = [(i, c) for i, c in enumerate(cand) if c.size]
        if not which:
            break
        mids = [0.5 * (runs[i][c] + runs[i][c + 1]) for i, c in which]
        allm = np.vstack(mids)
        long_enough = np.hypot(*(np.vstack([runs[i][c + 1] - runs[i][c] for i, c in which])[:, :2].T)) > 1e-4
        z = drop_points(sampler, cutter, allm[:, 0], allm[:, 1], d) + leave
        up_all = (z - allm[:, 2] > tol) & long_enough
        cand = [np.zeros(0, int) for _ in runs]
        pos = 0
        for (i, c), m in zip(which, mids):
            up = up_all[pos : pos + len(c)]
            zz = z[pos : pos + len(c)]
            pos += len(c)
            if not up.any():
                continue
            seg = c[up]
            new = m[up].copy()
            new[:, 2] = zz[up]
            runs[i] = np.insert(runs[i], seg + 1, new, axis=0)
            # after insertion, segment seg+k (k inserted before it) splits into two
            shift = np.arange(seg.size)
            first = seg + shift
            cand[i] = np.concatenate([first, first + 1])
    return runs


def _true_runs(mask):
    m = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[0::2], edges[1::2]))


def _links(sampler, cutter, st, runs, passes):
    """Surface-following moves between consecutive runs that are neighbours, else None.

    Links in the same direction are dropped together (one drop_lines call), so
    the ~200 links of a program cost about as much as one pass.
    """
    d = st.resolution
    limit = min(2.0 * (np.max(np.diff(passes)) if passes.size > 1 else st.cutter.radius), st.cutter.diameter)
    out = [None] * max(len(runs) - 1, 0)
    groups = {}
    for i in range(len(runs) - 1):
        p, q = runs[i][-1], runs[i + 1][0]
        gap = float(np.hypot(*(q[:2] - p[:2])))
        if gap > limit + 1e-9:
            continue
        if gap < 1e-9:
            out[i] = np.empty((0, 3))
            continue
        e = (q[:2] - p[:2]) / gap
        k = int(np.ceil(gap / d - 1e-9))  # points p + j d e, j = 1..k-1, then q
        xy = p[None, :2] + d * np.arange(1, k)[:, None] * e[None, :]
        if len(xy) and np.any(sampler.part_distance(xy[:, 0], xy[:, 1]) > st.margin + 1e-9):
            continue
        key = (round(e[0], 9), round(e[1], 9))
        groups.setdefault(key, []).append((i, p, k))
    for key, items in groups.items():
        e = np.array(key)
        n = max(k for _, _, k in items)
        if n <= 1:
            for i, _, _ in items:
                out[i] = np.empty((0, 3))
            continue
        origins = np.array([p[:2] + d * e for _, p, _ in items])
        z = drop_lines(sampler, cutter, origins, e, n - 1, d) + st.leave
        for row, (i, p, k) in enumerate(items):
            xy = origins[row][None, :] + d * np.arange(k - 1)[:, None] * e[None, :]
            out[i] = np.column_stack([xy, z[row, : k - 1]])
    # a link runs across the passes, where the tip height may be concave: refine it
    # together with its end points, then keep only its inner points
    todo = [i for i, l in enumerate(out) if l is not None]
    full = [np.vstack([runs[i][-1:], out[i], runs[i + 1][:1]]) for i in todo]
    full = refine(sampler, cutter, full, refine_tolerance(st.chord), st.leave, d)
    for i, f in zip(todo, full):
        out[i] = f[1:-1]
    return out


# -- stepover planning ------------------------------------------------------------


class _PassProbe:
    """Tip heights and along-slopes of a candidate pass, on the planner's sparse points."""

    def __init__(self, sampler, st, e1, e2, t0, n):
        self.sampler, self.st, self.e1, self.e2, self.t0, self.n = sampler, st, e1, e2, t0, n
        # A flat end's cusp beside its rim is the riser m s less |grad_x| x the half
        # chord sqrt(2 R s) its bottom spans there: where the gradient along the pass
        # changes sign that is a sharp V along the pass (on sample 4 it fell from 0.072
        # to 0.045 within 0.14 mm, and columns 0.3 mm apart left 0.063 against 0.05
        # asked), so a flat end is measured every R / 10 at least
        spacing = PLAN_SPACING if st.cutter.kind != "flat" else min(PLAN_SPACING, st.cutter.radius / 10)
        self.stride = max(1, int(round(spacing / st.resolution)))
        self._grids = {}
        self._measured = {}  # (across, row step) -> (first row, envelope) of candidates measured
        # rows of the cross-sections: eight per flat-surface stepover, at most 0.05 mm
        self.row = min(
            _BALL_ROW if st.cutter.kind == "ball" else _ROW, flat_stepover(st.cutter, st.scallop) / 8
        )
        idx = np.arange(0, n, self.stride)
        # every point within 1.5 R of the passes' ends: there the cutter reaches the
        # strip beside the part's edge only from positions to the side, and the cusps
        # it leaves change within a tenth of a millimetre along the pass (0.3 mm apart
        # they were missed: a bull nose left 0.013-0.019 mm against 0.01 asked, a 1 mm
        # ball on sample 4's 81-degree faces down to its edge 0.023)
        m = min(int(np.ceil(1.5 * st.cutter.radius / st.resolution)), n)
        idx = np.union1d(idx, np.concatenate([np.arange(m), np.arange(n - m, n)]))
        self.idx = idx
        self.along = t0 + st.resolution * idx
        # what an infinitely fine stepover would leave, on the verification's lattice
        self.opening = Opening.over(sampler, st.cutter, st.resolution)

    def pass_at(self, s):
        """(across position, tips at every point of the pass; inf where not in the program).

        The tips are the program's own (polished on steep faces, a flat end's at
        its rim): lattice tips stand up to 0.03 mm low on sample 4's 80-degree
        faces, which the planner would take for stock already cut.
        """
        o = self.t0 * self.e1 + s * self.e2
        full = drop_lines(self.sampler, self.st.cutter, o[None, :], self.e1, self.n, self.st.resolution)[0]
        # positions off the part (beyond the margin) are not in the program
        t = self.st.resolution * np.arange(self.n)
        gone = (
            self.sampler.part_distance(o[0] + t * self.e1[0], o[1] + t * self.e1[1]) > self.st.margin + 1e-9
        )
        return s, np.where(gone, np.inf, full)

    def envelope(self, p, dy, cols):
        """Lowest the cutter of pass p reaches at lateral distance dy (rows x len(cols)) in sparse columns `cols`.

        The envelope is taken over the pass's own tool positions: the min over
        positions k within reach of tip_k + h(distance). The swept cylinder of
        the local slope (scallop.py) is not enough: the lowest point of a swept
        cutter lies up to R away along the pass (a flat or bull-nose bottom
        always, a ball on a slope t at R t / sqrt(1 + t^2)), where a curved pass
        has left its tangent line by ~curvature x R^2 / 2 (0.036 mm on a gentle
        0.008 /mm bend; on sample 4's steep saddle the cylinder stood 0.2 mm
        above a 1 mm ball's sweep, the columns looked untouched and the planner
        left a 0.13 mm scallop). For a ball or bull nose the minimum is a
        smooth interior one, so positions 0.1 mm apart miss it by a second-order
        amount; a flat end's minimum sits where its rim leaves the column, so
        the tips there are interpolated at exactly that reach as well.
        """
        return self.envelope_many([p], np.zeros(np.size(cols), int), dy, cols)

    def envelope_many(self, passes, pid, dy, cols):
        """envelope() with column j's pass passes[pid[j]]: the cusp's fine search asks
        for many passes, each at a few columns, and one call costs what one pass's does."""
        cut, d, R = self.st.cutter, self.st.resolution, self.st.cutter.radius
        cols = np.asarray(cols)
        full = np.stack([q[1] for q in passes])
        a_flat = R - cut.corner_radius
        dy = np.abs(np.asarray(dy, float))
        at = self.idx[cols]
        env = np.full(np.broadcast_shapes(dy.shape, (1, at.size)), np.inf)
        # the flat bottom: a plain window minimum of the tips (h = 0 there), one
        # minimum filter per distinct window width
        w_flat = np.floor(np.sqrt(np.maximum(a_flat**2 - dy**2, 0.0)) / d + 1e-9).astype(int)
        w_flat = np.where(dy <= a_flat, w_flat, -1)
        for w in np.unique(w_flat[w_flat >= 0]):
            lowest = ndimage.minimum_filter1d(full, 2 * w + 1, axis=1, mode="constant", cval=np.inf)[pid, at]
            env = np.where(w_flat == w, np.minimum(env, lowest[None, :]), env)
        if cut.kind == "flat":
            # its lowest reach is at the rim: interpolate the tips exactly there too
            reach = np.sqrt(np.maximum(R * R - dy * dy, 0.0)) / d
            for sign in (-1.0, 1.0):
                env = np.minimum(env, self._tips_at(full, pid, at[None, :] + sign * reach, dy <= R))
        else:
            env = np.minimum(env, self._corner_envelope(full, pid, at, dy, w_flat))
        return np.where(dy <= R + 1e-12, env, np.inf)

    @staticmethod
    def _tips_at(full, pid, f, ok):
        """Tips of pass pid (per column) interpolated at fractional positions f; inf off the
        pass or next to a position that is not in the program."""
        n = full.shape[1]
        ok = ok & (f >= 0) & (f <= n - 1)
        i = np.clip(np.floor(f).astype(int), 0, n - 2)
        u = f - i
        lo, hi = full[pid, i], full[pid, i + 1]
        with np.errstate(invalid="ignore"):
            val = np.where(u == 0, lo, lo + u * (hi - lo))
        return np.where(ok & np.isfinite(val), val, np.inf)

    def _corner_envelope(self, full, pid, at, dy, w_flat, budget=400_000):
        """min over positions k whose ball or bull-nose corner passes over the column: tip_k + h,
        then the moves beside the lowest position swept exactly.

        h depends on (k, dy) only, so it is tabled once per call. With one dy per
        row (cached rows, many columns) the loop runs over k on the rows each k
        reaches; with a dy per element (the cusp's fine search, a few thousand
        elements) all k are taken at once, in chunks of `budget` elements.
        """
        cut, d, R = self.st.cutter, self.st.resolution, self.st.cutter.radius
        m = int(np.floor(R / d + 1e-9))
        pad = np.pad(full, ((0, 0), (m, m)), constant_values=np.inf)
        ks = np.arange(-m, m + 1)
        shape = np.broadcast_shapes(dy.shape, (1, at.size))
        env = np.full(shape, np.inf)
        best = np.zeros(shape, int)  # k of the lowest position
        w_all = np.floor(np.sqrt(np.maximum(R * R - dy * dy, 0.0)) / d + 1e-9)
        kk = np.abs(ks).reshape((-1,) + (1,) * dy.ndim)
        ring = (kk > w_flat[None]) & (kk <= w_all[None]) & (dy <= R)[None]
        H = cut.profile(np.minimum(np.hypot(kk * d, dy[None]), R))
        if dy.shape[1] == 1:
            # one min-plus product: rows x positions (H) against positions x columns
            # (the tips), in row chunks of `budget` elements, single precision
            # relative to the lowest tip (the loop over positions it replaces was
            # half of a finishing plan's time)
            tips = pad[pid[None, :], at[None, :] + m + ks[:, None]]  # (k, cols)
            fin = np.isfinite(tips)
            ref = float(tips[fin].min()) if fin.any() else 0.0
            t32 = (tips - ref).astype(np.float32)
            h32 = np.where(ring[:, :, 0], H[:, :, 0], np.inf).T.astype(np.float32)  # (rows, k)
            t32 = np.ascontiguousarray(t32.T)  # (cols, k)
            live = np.flatnonzero(np.isfinite(h32).any(axis=1))
            step = max(1, budget // max(t32.size, 1))
            for r0 in range(0, live.size, step):
                r = live[r0 : r0 + step]
                cand = h32[r][:, None, :] + t32[None, :, :]  # positions innermost: fast argmin
                j = np.argmin(cand, axis=2)
                low = np.take_along_axis(cand, j[:, :, None], axis=2)[:, :, 0]
                env[r] = np.where(np.isfinite(low), low.astype(np.float64) + ref, np.inf)
                best[r] = ks[j]
        else:
            tips = pad[pid[None, :], at[None, :] + m + ks[:, None]][:, None, :]  # (k, 1, cols)
            step = max(1, budget // max(env.size, 1))
            for k0 in range(0, ks.size, step):
                sl = slice(k0, k0 + step)
                cand = np.where(ring[sl], tips[sl] + H[sl], np.inf)
                j = np.argmin(cand, axis=0)
                low = np.take_along_axis(cand, j[None], axis=0)[0]
                better = low < env
                env = np.where(better, low, env)
                best = np.where(better, ks[k0 + j], best)
        return self._between_positions(full, pid, at, dy, env, best)

    def _between_positions(self, full, pid, at, dy, env, best):
        """env lowered to what the straight moves on either side of each element's
        lowest position cut (segments.py, exact).

        The program moves in straight lines between positions d apart; on a face
        steep along the pass the cutter's h'' is large (526 /mm for a 1 mm ball
        at 81 degrees) and the lowest of the positions alone stood up to h'' (d /
        2)^2 / 2 above the sweep (0.026 mm at d = 0.02): the planner took that for
        stock left and stepped over far finer than the verification needed.
        """
        cut, d = self.st.cutter, self.st.resolution
        n = full.shape[1]
        pos = at[None, :] + best
        rows = np.broadcast_to(pid[None, :], pos.shape)
        out = env
        for j0 in (pos - 1, pos):
            ok = np.isfinite(env) & (j0 >= 0) & (j0 <= n - 2)
            j0 = np.clip(j0, 0, n - 2)
            a, b = full[rows, j0], full[rows, j0 + 1]
            ok &= np.isfinite(a) & np.isfinite(b)
            a, b = np.where(ok, a, 0.0), np.where(ok, b, 0.0)
            swept = min_over_segment(cut, (at[None, :] - j0) * d, dy, d, 0.0, b - a, a)
            out = np.where(ok, np.minimum(out, swept), out)
        return out

    def _row_step(self, gap):
        """Row spacing for a gap between passes: the global spacing, halved until it is at
        most an eighth of the gap (a ball's contact on a steep face must fall near a row,
        or the column looks untouched and is left out: sample 4's 80-degree faces then let
        the planner jump, 0.49 mm left). Powers of two keep the rows on a few global
        grids, so the placed passes merged on them serve many candidates."""
        level = max(0, int(np.ceil(np.log2(self.row * 8 / max(gap, 1e-3)) - 1e-9)))
        return self.row / 2**level

    def _placed(self, step, done):
        """The placed passes merged on the row grid of spacing `step`, up to date with `done`."""
        sa = done[-1][0]
        reach = 2 * self.st.cutter.radius
        # grids no pass can still reach are dropped
        for key in [k for k, g in self._grids.items() if g.top_y() < sa - reach]:
            del self._grids[key]
        grid = self._grids.get(step)
        if grid is None:
            grid = self._grids[step] = _PlacedRows(self, step)
        grid.catch_up(done)
        return grid

    def points(self, s):
        return (
            self.along[None, :] * self.e1[0] + np.asarray(s)[:, None] * self.e2[0],
            self.along[None, :] * self.e1[1] + np.asarray(s)[:, None] * self.e2[1],
        )

    def scallop(self, done, b):
        """Largest scallop the candidate pass b leaves against the passes already placed.

        In the cross-section at each sparse column, each pass cuts down to its
        swept profile; the stock is the lowest of them. The cusp that b closes
        lies between the *contact points* of the last pass and of b (on a
        slope across the passes the cutter touches uphill of its axis, up to
        R sin(slope) away), so that interval is where the scallop is measured.
        Columns where either pass touches nothing in the cross-section (a
        concave region tighter than the cutter) are left out.
        """
        cut = self.st.cutter
        R = cut.radius
        a = done[-1]
        sa, sb = a[0], b[0]
        step = self._row_step(sb - sa)
        k0, k1 = int(np.floor((sa - R) / step)), int(np.ceil((sb + R) / step)) + 1
        ys = step * np.arange(k0, k1)
        cols_all = np.arange(self.along.size)
        # every placed pass whose cutter reaches the interval (with small steps, a
        # flat bottom on a cross slope, 90 of them), merged once on a global grid
        grid = self._placed(step, done)
        Z, on, op, placed, owner, env_a = grid.rows(k0, k1)
        env_b = self.envelope(b, (ys - b[0])[:, None], cols_all)
        # the pass placed next is one of these candidates: its rows are merged from here
        self._measured[(b[0], step)] = (k0, env_b)
        stock = np.minimum(placed, env_b)
        who = np.where(env_b < placed, len(done), owner)  # which pass leaves the stock there
        # a pass touches where it comes nearest the opened design, the surface the
        # cutter can reach at all: beside sample 4's 81-degree faces down to its
        # edge no position comes within 0.004 mm of the design itself, and a ball's
        # column there looked untouched and was left out (0.011 left)
        surface = np.maximum(Z, op)
        gap_a = np.where(on, env_a - surface, np.inf)
        gap_b = np.where(on, env_b - surface, np.inf)
        ca, cb = np.argmin(gap_a, axis=0), np.argmin(gap_b, axis=0)
        cols = np.arange(Z.shape[1])
        rows = np.arange(ys.size)[:, None]
        if cut.kind == "ball":
            # a ball touches at one row of a column; a column where either pass
            # touches nothing (a concave region tighter than the cutter) is left out
            touch = (gap_a[ca, cols] <= 0.3 * self.st.scallop) & (gap_b[cb, cols] <= 0.3 * self.st.scallop)
            inside = touch[None, :] & on
        else:
            # A flat bottom touches a whole band at once (on a flat, under all
            # its bottom): of equal contacts take a's nearest b and b's nearest a
            tie = 0.1 * self.st.scallop
            near_a = gap_a <= gap_a.min(axis=0) + tie
            near_b = gap_b <= gap_b.min(axis=0) + tie
            ca = ys.size - 1 - np.argmax(near_a[::-1], axis=0)
            cb = np.argmax(near_b, axis=0)
            # and a column either pass touches nothing in is left out as for a ball: on
            # sample 3's corner (x 99, y 0; slopes 0.83 across, 0.15 along, downhill to
            # both) only positions 2.6 mm in reach the edge row, the first pass stood
            # 0.40 above it whatever the step, and the planner crawled at its 0.01 minimum
            touch = (gap_a.min(axis=0) <= 0.3 * self.st.scallop) & (
                gap_b.min(axis=0) <= 0.3 * self.st.scallop
            )
            inside = touch[None, :] & on
        # The rows between the contacts: positions between a and b touch there,
        # later passes touch beyond b's contact, so the rows beyond are not b's to
        # hold (on a cross slope a flat bottom leaves m x 2R under its own bottom
        # there, which the opening, reached from the later positions, rightly
        # calls reachable). Measured above the opening, as the verification
        # measures: rows the opening leaves high are the cutter's size, not the
        # stepover's, and its residue within the reach tolerance is no scallop
        # (counted, it made the planner 17 % too fine on sample 4's steep faces)
        lo, hi = np.minimum(ca, cb), np.maximum(ca, cb)
        inside = inside & (rows >= lo[None, :]) & (rows <= hi[None, :])
        above, reach = self.opening.above_at(stock, Z, op)
        val = np.where(inside & reach, above, -np.inf)
        if not np.isfinite(val).any():
            return 0.0
        coarse = float(np.max(val))
        # the cusp is a sharp V between two cutter profiles: sampled `step` apart
        # its top is missed by up to slope x step / 2 (~20 % of the scallop for a
        # ball), so look again on a fine grid around each column's highest row
        # only columns whose coarse cusp could still beat the highest one: the top is
        # missed by ~20 % of the scallop, so columns 40 % of the request below it cannot
        col_max = np.max(val, axis=0)
        cols_ok = np.flatnonzero(np.isfinite(col_max) & (col_max >= coarse - 0.4 * self.st.scallop))
        r = np.argmax(val[:, cols_ok], axis=0)
        S = ys[r][None, :] + step * np.linspace(-1.0, 1.0, 17)[:, None]
        a1 = self.along[cols_ok][None, :]
        Xf = a1 * self.e1[0] + S * self.e2[0]
        Yf = a1 * self.e1[1] + S * self.e2[1]
        Zf = self.sampler.z(Xf, Yf)
        onf = self.sampler.on_part(Xf, Yf)
        fine = np.full(S.shape, np.inf)
        rr = np.clip(r[None, :] + np.array([-1, 0, 1])[:, None], 0, ys.size - 1)
        owners = who[rr, cols_ok[None, :]]
        smooth = self._cusp_of_two(fine, owners, len(done), r, ys.size, env_a, env_b, cols_ok)
        exact = np.flatnonzero(~smooth)
        if exact.size:
            self._cusp_exact(fine, done, b, owners, S, cols_ok, exact)
        above, reach = self.opening.above(fine, Zf, Xf, Yf)
        fine = np.where(onf & reach, above, -np.inf)
        return max(coarse, float(np.max(fine)))

    def _cusp_of_two(self, fine, owners, nb, r, nrows, env_a, env_b, cols_ok):
        """Fill `fine` (17 rows x columns) where the cusp lies between the last pass and
        the candidate alone; returns the columns filled.

        A ball's or bull nose's envelope is smooth across the cusp (a circle of
        the corner), so the quadratic through its three rows around the coarse
        top gives it on the fine rows within a third-order term: ~(step)^3 / R^2,
        1e-5 mm at 0.05 mm rows. Both envelopes are on the rows already, so the
        fine search costs arithmetic, not a sweep of every position again (that
        sweep was a third of the planner's time). A flat end's envelope has a
        kink at its rim; it, and columns where an earlier pass leaves the stock,
        are swept exactly.
        """
        if self.st.cutter.kind == "flat":
            return np.zeros(r.size, bool)
        ok = (r >= 1) & (r <= nrows - 2) & np.all((owners == nb) | (owners == nb - 1), axis=0)
        rows = np.clip(r[None, :] + np.array([-1, 0, 1])[:, None], 0, nrows - 1)
        ea, eb = env_a[rows, cols_ok[None, :]], env_b[rows, cols_ok[None, :]]
        ok &= np.all(np.isfinite(ea) & np.isfinite(eb), axis=0)
        u = np.linspace(-1.0, 1.0, fine.shape[0])[:, None]

        def quad(e):
            return e[1] + 0.5 * (e[2] - e[0]) * u + 0.5 * (e[2] - 2 * e[1] + e[0]) * u * u

        with np.errstate(invalid="ignore"):
            fine[:, ok] = np.minimum(quad(ea[:, ok]), quad(eb[:, ok]))
        return ok

    def _cusp_exact(self, fine, done, b, owners, S, cols_ok, which):
        """Fill `fine` at columns `which` with every pass that leaves the stock on the rows
        around the coarse top, swept exactly at the fine rows."""
        owners = owners[:, which]
        ids = np.unique(owners)
        passes = [b if i == len(done) else done[i] for i in ids]
        # every (owner, column) pair once, all in one call
        pick = np.zeros((ids.size, which.size), bool)
        pick[np.searchsorted(ids, owners), np.arange(which.size)[None, :]] = True
        pid, c = np.nonzero(pick)
        across = np.array([q[0] for q in passes])[pid]
        env = self.envelope_many(passes, pid, S[:, which[c]] - across[None, :], cols_ok[which[c]])
        sub = np.full((S.shape[0], which.size), np.inf)
        np.minimum.at(sub.T, c, env.T)
        fine[:, which] = sub


class _PlacedRows:
    """The passes placed so far, merged on one global grid of cross-section rows y = k step.

    Every candidate pass is measured against all the placed passes its cutter
    could meet (2R / s of them: 90 for a flat end at 0.065 mm on a steep cross
    slope). Each placed pass is merged into the grid's stock once (with the
    index of the pass that leaves each row's stock, for the cusp's fine
    search), and the design, the footprint and the opening on the rows are read
    once, so a candidate costs its own envelope and a slice.
    """

    def __init__(self, probe, step):
        self.probe, self.step = probe, step
        self.k0, self.n = 0, 0  # rows k0 .. k0 + n - 1 are held
        ncol = probe.along.size
        self.Z, self.op, self.stock = (np.empty((0, ncol)) for _ in range(3))
        self.on = np.empty((0, ncol), bool)
        self.owner = np.empty((0, ncol), int)
        self.merged = 0  # passes of `done` merged so far
        self.last = (0, np.empty((0, ncol)))  # (first row, envelope) of the last merged pass

    def top_y(self):
        return (self.k0 + self.n) * self.step

    def _arrays(self):
        return self.Z, self.on, self.op, self.stock, self.owner

    def _hold(self, k0, k1):
        """Hold at least rows k0..k1-1. Rows below k0 are dropped: the passes only move
        on (k0 follows the last placed pass), so no row is asked for again."""
        assert self.n == 0 or k0 >= self.k0, "the planner's rows went back"
        if self.n == 0 or k0 >= self.k0 + self.n:
            self.k0, self.n = k0, 0
            self.Z, self.on, self.op, self.stock, self.owner = (a[:0] for a in self._arrays())
        if k1 > self.k0 + self.n:
            new = self._new_rows(self.k0 + self.n, k1)
            self.Z, self.on, self.op, self.stock, self.owner = (
                np.concatenate([o, n]) for o, n in zip(self._arrays(), new)
            )
            self.n = k1 - self.k0
        if k0 > self.k0:
            cut = k0 - self.k0
            self.Z, self.on, self.op, self.stock, self.owner = (a[cut:] for a in self._arrays())
            self.k0, self.n = k0, self.n - cut

    def _new_rows(self, k0, k1):
        pr = self.probe
        X, Y = pr.points(self.step * np.arange(k0, k1))
        Z, on = pr.sampler.z(X, Y), pr.sampler.on_part(X, Y)
        op = pr.opening.at(X, Y)
        return Z, on, op, np.full(Z.shape, np.inf), np.full(Z.shape, -1)

    def catch_up(self, done):
        """Merge the passes of `done` not merged yet, on the rows a candidate after the
        last of them is measured on (from R below it: nothing lower is measured again)."""
        R = self.probe.st.cutter.radius
        first = int(np.floor((done[-1][0] - R) / self.step))
        while self.merged < len(done) and done[self.merged][0] + R < first * self.step:
            self.merged += 1
        while self.merged < len(done):
            p = done[self.merged]
            j0 = max(int(np.ceil((p[0] - R) / self.step)), first)
            j1 = int(np.floor((p[0] + R) / self.step)) + 1
            self._hold(first, j1)
            ys = self.step * np.arange(j0, j1)
            known = self.probe._measured.get((p[0], self.step))
            if known is not None and known[0] <= j0 and known[0] + known[1].shape[0] >= j1:
                env = known[1][j0 - known[0] : j1 - known[0]]
            else:
                env = self.probe.envelope(p, (ys - p[0])[:, None], np.arange(self.probe.along.size))
            sl = slice(j0 - self.k0, j1 - self.k0)
            lower = env < self.stock[sl]
            self.stock[sl] = np.where(lower, env, self.stock[sl])
            self.owner[sl] = np.where(lower, self.merged, self.owner[sl])
            self.last = (j0, env)
            self.merged += 1
        self.probe._measured.clear()

    def rows(self, k0, k1):
        """(design, on part, opening, placed stock, owner, last pass's envelope) on rows k0..k1-1."""
        self._hold(k0, k1)
        sl = slice(k0 - self.k0, k1 - self.k0)
        j0, env = self.last
        last = np.full((k1 - k0, env.shape[1]), np.inf)
        a, b = max(k0, j0), min(k1, j0 + env.shape[0])
        if a < b:
            last[a - k0 : b - k0] = env[a - j0 : b - j0]
        return self.Z[sl], self.on[sl], self.op[sl], self.stock[sl], self.owner[sl], last


def _plan_passes(sampler, st, e1, e2, t0, n, s0, s1):
    h = st.scallop
    lo_ok, hi_ok, aim = 0.90 * h, 0.98 * h, 0.95 * h
    probe = _PassProbe(sampler, st, e1, e2, t0, n)
    # never more than 1.5 x the flat-surface stepover: convex surfaces allow a
    # little more, but a cross-section where nothing could be measured (the
    # pass along an uphill edge touching only the edge) must not open a gap
    s_cap = min(0.95 * st.cutter.diameter, 1.5 * flat_stepover(st.cutter, h))
    # a flat bottom on a slope m leaves a staircase of risers m x s whatever its
    # diameter, so the floor is 2 % of the ball-like stepover, not of the flat one
    # (0.108 mm for a 6 mm flat end held 0.06 where 0.05 was asked on a 0.4 slope)
    s_min = max(
        0.02 * min(flat_stepover(st.cutter, h), ball_stepover(st.cutter.radius, h)), st.resolution / 10
    )
    guess = flat_stepover(st.cutter, h)
    done = [probe.pass_at(s0)]
    passes = [s0]
    while passes[-1] < s1 - 1e-9:
        sa = passes[-1]
        best_ok, best_p, worst = None, None, np.inf
        s = min(guess, s1 - sa)
        for _ in range(10):
            cand = probe.pass_at(sa + s)
            sc = probe.scallop(done, cand)
            if sc <= hi_ok:
                if best_ok is None or s > best_ok:
                    best_ok, best_p = s, cand
                if sc >= lo_ok or sa + s >= s1 - 1e-9 or s >= s_cap - 1e-9:
                    break
            else:
                worst = min(worst, s)
            if sc > 1e-12:
                nxt = s * np.sqrt(aim / sc)
            else:
                nxt = 2 * s
            lo_b = best_ok if best_ok is not None else s_min
            nxt = min(nxt, s_cap, s1 - sa, worst)
            if not (lo_b < nxt < worst) or abs(nxt - s) < 1e-4:
                nxt = 0.5 * (lo_b + min(worst, s_cap, s1 - sa))
            if abs(nxt - s) < 1e-5:
                break
            s = nxt
        if best_ok is None:
            best_ok = s_min
            best_p = probe.pass_at(sa + s_min)
        nxt = min(sa + best_ok, s1)
        if s1 - nxt < s_min:
            # a last sliver narrower than the smallest step: end on the boundary
            # instead of adding a pass a fraction of a micron from it
            nxt = s1
            best_p = probe.pass_at(s1)
        passes.append(nxt)
        done.append(best_p if best_p[0] == nxt else probe.pass_at(nxt))
        guess = best_ok
    return np.array(passes), np.stack([p[1] for p in done])


# -- point reduction ----------------------------------------------------------------


def reduce_polyline(p, tol, keep=None):
    """Ramer-Douglas-Peucker on a 3-D polyline: no dropped point is more than `tol`
    from its replacing move, vertically at the same xy nor sideways.

    Level-synchronous: every round splits *all* segments whose farthest point
    is beyond the tolerance at once, so the work is a few vectorised passes
    over the points (about log2 of their number), not one Python call per
    kept point. `keep` marks points that must stay (the ends of passes and
    links of a linked run), which also splits the work into independent pieces.
    """
    p = np.asarray(p, float)
    n = len(p)
    if n <= 2:
        return p
    keep = np.zeros(n, bool) if keep is None else np.array(keep, bool, copy=True)
    keep[0] = keep[-1] = True
    idx = np.arange(n)
    while True:
        kept = np.flatnonzero(keep)
        seg = np.searchsorted(kept, idx, side="right") - 1
        seg = np.minimum(seg, len(kept) - 2)
        a, b = kept[seg], kept[seg + 1]
        A, B = p[a], p[b]
        AB = B[:, :2] - A[:, :2]
        L2 = np.einsum("ij,ij->i", AB, AB)
        AP = p[:, :2] - A[:, :2]
        t = np.einsum("ij,ij->i", AP, AB) / np.where(L2 > 0, L2, 1.0)
        t = np.clip(np.where(L2 > 0, t, 0.0), 0, 1)
        D = AP - t[:, None] * AB
        # vertical error at the same xy (what gouges), and any sideways error (corners)
        dz = np.abs(p[:, 2] - (A[:, 2] + t * (B[:, 2] - A[:, 2])))
        dist = np.maximum(np.sqrt(np.einsum("ij,ij->i", D, D)), dz)
        dist[keep] = 0.0
        segmax = np.maximum.reduceat(dist, kept[:-1])
        far = (dist > tol) & (dist == segmax[seg])
        if not far.any():
            return p[keep]
        cand = np.flatnonzero(far)
        _, first = np.unique(seg[cand], return_index=True)
        keep[cand[first]] = True
