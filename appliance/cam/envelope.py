"""What a pass cuts: its tool tips and the lowest its swept cutter reaches beside it.

The stepover planner (passplan.py) measures a candidate pass against the
passes already placed in cross-sections across them; each pass's cut in a
cross-section is its envelope, the minimum over its own tool positions of
tip + cutter profile, with the straight moves between positions swept
exactly. The planner reads it on sparse columns (every 0.3 mm along a pass,
every position near its ends): `PassEnvelope` holds those columns.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..forks import in_parts
from .contact import drop_lines
from .opening import Opening
from .scallop import flat_stepover
from .segments import min_over_segment

PLAN_SPACING = 0.3  # mm between the points the planner measures along a pass
_ROW = 0.05  # mm between the rows of the planner's cross-sections
_ENV_BLOCK = 50_000  # elements of one envelope call (see envelope_many)
_BALL_ROW = 0.1  # for a ball: its envelope is a circle across the cusp, which the
# quadratic through three rows 0.1 apart gives within 1e-5 mm


class PassEnvelope:
    """Tip heights and envelopes of a candidate pass, on the planner's sparse points."""

    def __init__(self, sampler, st, e1, e2, t0, n, opening=None):
        """`opening`: the one to read (bands.py builds it once for both of its planners);
        by default it is built here, over the whole part, in halves of rows on the cores."""
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
        self._kept = None  # across position of the candidate whose envelope is kept (cusps.py)
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
        # a column beyond the footprint's extent along the passes is off the part on every
        # row, where nothing is measured: with the rim (margin RIM) the passes' ends are a
        # radius out, 13 % of the columns and of the envelopes' work on sample 1
        lo, hi = sampler.footprint_extent(e1)
        t = t0 + st.resolution * idx
        idx = idx[(t >= lo - 1e-6) & (t <= hi + 1e-6)]
        self.idx = idx
        self.along = t0 + st.resolution * idx
        # what an infinitely fine stepover would leave, on the verification's lattice
        self.opening = planner_opening(sampler, st) if opening is None else opening

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

        A column with none of the pass's tips in the program within the cutter's reach is
        inf, which is what the whole computation gives it: such columns are not computed
        (off a round part's outline, the dense columns at the passes' ends most of all, a
        fifth of the daemon's sphere's).
        """
        cols = np.asarray(cols)
        reached = self._reaches(p[1])[cols]
        dy = np.asarray(dy, float)
        env = np.full(np.broadcast_shapes(dy.shape, (1, cols.size)), np.inf)
        if reached.any():
            dy_r = dy[:, reached] if dy.ndim == 2 and dy.shape[1] > 1 else dy
            env[:, reached] = self.envelope_many([p], np.zeros(int(reached.sum()), int), dy_r, cols[reached])
        return env

    def _reaches(self, tips):
        """Per column: a finite tip within the cutter's reach along the pass, or one position
        more (a flat end's rim is read between two positions)."""
        m = int(np.floor(self.st.cutter.radius / self.st.resolution + 1e-9)) + 1
        count = np.concatenate([[0], np.cumsum(np.isfinite(tips))])
        lo = np.clip(self.idx - m, 0, tips.size)
        hi = np.clip(self.idx + m + 1, 0, tips.size)
        return count[hi] > count[lo]

    def envelope_many(self, passes, pid, dy, cols):
        """envelope() with column j's pass passes[pid[j]]: the cusp's fine search asks
        for many passes, each at a few columns, and one call costs what one pass's does.

        Every element is its own minimum, so a large call is made in blocks of rows (or of
        columns) of _ENV_BLOCK elements: the exact sweep's temporaries are ~30 arrays of
        the call's size, and the 6300 rows x 414 columns a candidate a hundredth of a
        millimetre over the rim asks for were 600 MB of a finishing plan's 886 MB peak."""
        cols, pid = np.asarray(cols), np.asarray(pid)
        dy = np.asarray(dy, float)
        rows, ncol = np.broadcast_shapes(dy.shape, (1, cols.size))
        if rows * ncol <= _ENV_BLOCK:
            return self._envelope_block(passes, pid, dy, cols)
        if dy.shape[1] == 1:
            step = max(1, _ENV_BLOCK // max(ncol, 1))
            blocks = [self._envelope_block(passes, pid, dy[r : r + step], cols) for r in range(0, rows, step)]
            return np.concatenate(blocks, axis=0)
        step = max(1, _ENV_BLOCK // max(rows, 1))
        blocks = [
            self._envelope_block(passes, pid[c : c + step], dy[:, c : c + step], cols[c : c + step])
            for c in range(0, ncol, step)
        ]
        return np.concatenate(blocks, axis=1)

    def _envelope_block(self, passes, pid, dy, cols):
        cut, d, R = self.st.cutter, self.st.resolution, self.st.cutter.radius
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
                # only the positions the rows' corners reach (|k| <= w_all: a row 0.9 R
                # across reaches 44 % of them); beyond, h is inf on every row of the chunk
                w = int(w_all[r, 0].max())
                k = slice(m - w, m + w + 1)
                cand = h32[r][:, None, k] + t32[None, :, k]  # positions innermost: fast argmin
                j = np.argmin(cand, axis=2)
                low = np.take_along_axis(cand, j[:, :, None], axis=2)[:, :, 0]
                env[r] = np.where(np.isfinite(low), low.astype(np.float64) + ref, np.inf)
                best[r] = j - w
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
        dy = np.broadcast_to(dy, pos.shape)
        out = env.copy()
        for j0 in (pos - 1, pos):
            ok = np.isfinite(env) & (j0 >= 0) & (j0 <= n - 2)
            j0 = np.clip(j0, 0, n - 2)
            a, b = full[rows, j0], full[rows, j0 + 1]
            ok &= np.isfinite(a) & np.isfinite(b)
            # only the elements in reach of a move (rows beyond the cutter's reach are
            # inf: 10-20 % of a candidate's, whose sweep was thrown away)
            k = np.nonzero(ok)
            a, b = a[k], b[k]
            swept = min_over_segment(cut, (at[k[1]] - j0[k]) * d, dy[k], d, 0.0, b - a, a)
            out[k] = np.minimum(out[k], swept)
        return out

    def points(self, s):
        return (
            self.along[None, :] * self.e1[0] + np.asarray(s)[:, None] * self.e2[0],
            self.along[None, :] * self.e1[1] + np.asarray(s)[:, None] * self.e2[1],
        )


def planner_opening(sampler, st) -> Opening:
    """What an infinitely fine stepover would leave, on the verification's lattice: over the
    whole part and the margin, in halves of rows on the cores where forking is allowed."""
    return Opening.over(sampler, st.cutter, st.resolution, pad=st.margin, split=in_parts)
