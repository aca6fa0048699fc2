"""The scallop a candidate pass leaves: cusps between it and the passes placed.

The planner (passplan.py) does not trust the flat-surface formula: for a
candidate next pass it drops the cutter along it, then measures the actual scallop between it and the previous pass with the
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
"""

from __future__ import annotations

import numpy as np

from .envelope import PassEnvelope


class PassProbe(PassEnvelope):
    """A pass's envelope measured against the placed passes: the scallop it would leave."""

    def _row_step(self, gap):
        """Row spacing for a gap between passes: the global spacing, halved until it is at
        most an eighth of the gap (a ball's contact on a steep face must fall near a row,
        or the column looks untouched and is left out: sample 4's 80-degree faces then let
        the planner jump, 0.49 mm left). Powers of two keep the rows on a few global
        grids, so the placed passes merged on them serve many candidates."""
        level = max(0, int(np.ceil(np.log2(self.row * 8 / max(gap, 1e-3)) - 1e-9)))
        return self.row / 2**level

    def keep_only(self, s):
        """Keep the envelope of the candidate at s (the planner's best so far) and no other: the
        pass it places is that one, whose envelope is then merged, not swept again (when only
        the last candidate's was kept, sweeping the others again was a third of the planner's
        time with the rim). At most two are held: this one and the latest."""
        self._kept = s
        self._forget_others()

    def _forget_others(self):
        for key in [k for k in self._measured if k[0] != self._kept]:
            del self._measured[key]

    def placed_envelope(self, p, step, j0, j1):
        """Pass p's envelope on rows j0..j1-1 of the grid of spacing `step`: the one measured
        when p was a candidate, where it covers those rows, else swept now."""
        known = self._measured.get((p[0], step))
        if known is not None and known[0] <= j0 and known[0] + known[1].shape[0] >= j1:
            return known[1][j0 - known[0] : j1 - known[0]]
        ys = step * np.arange(j0, j1)
        return self.envelope(p, (ys - p[0])[:, None], np.arange(self.along.size))

    def forget_candidates(self):
        """A pass was placed: the candidates measured for it are of no use to the next one."""
        self._measured.clear()
        self._kept = None

    def _placed(self, step, done):
        """The placed passes merged on the row grid of spacing `step`, up to date with `done`."""
        sa = done[-1][0]
        reach = 2 * self.st.cutter.radius
        # grids no pass can still reach are dropped
        for key in [k for k, g in self._grids.items() if g.top_y() < sa - reach]:
            del self._grids[key]
        grid = self._grids.get(step)
        if grid is None:
            grid = self._grids[step] = PlacedRows(self, step)
        grid.catch_up(done)
        return grid

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
        # every placed pass whose cutter reaches the interval (with small steps, a
        # flat bottom on a cross slope, 90 of them), merged once on a global grid
        grid = self._placed(step, done)
        Z, on, op, placed, owner, env_a = grid.rows(k0, k1)
        env_b = self.envelope(b, (ys - b[0])[:, None], np.arange(self.along.size))
        # the pass placed next is one of these candidates: its rows are merged from here
        self._forget_others()
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
            # a ball touches at one row of a column: its gap there is the column's
            closest_a, closest_b = gap_a[ca, cols], gap_b[cb, cols]
        else:
            # A flat bottom touches a whole band at once (on a flat, under all
            # its bottom): of equal contacts take a's nearest b and b's nearest a
            tie = 0.1 * self.st.scallop
            near_a = gap_a <= gap_a.min(axis=0) + tie
            near_b = gap_b <= gap_b.min(axis=0) + tie
            ca = ys.size - 1 - np.argmax(near_a[::-1], axis=0)
            cb = np.argmax(near_b, axis=0)
            closest_a, closest_b = gap_a.min(axis=0), gap_b.min(axis=0)
        # A column the candidate touches nothing in (a concave region tighter than the
        # cutter) is left out, and so is one the placed pass touches nothing in - except
        # for the first step of a plan. Its placed pass runs off the outline, and beside a
        # wall it reaches the wall's top edge only at its full radius, a hair the rows miss:
        # left out, that step went unmeasured, jumped 1.6 mm, and the daemon's sphere kept
        # a 2.1 mm ridge along its edges parallel to the passes (a bull nose 8 mm, the whole
        # wall). There the rows from the placed pass's axis to the candidate's contact are
        # measured, where the candidate leaves the stock (an earlier cusp out of its reach
        # does not shrink with the step). Measured so on every step, the planner crawled at
        # pass ends mid-part (the demo's far planner 4.8 s of measuring for 2.5, +43 MB).
        # Not for a flat end yet: its passes then stand on that wall, where its drops cut
        # 0.015 mm in at the pass ends (it leaves the wall as it did, 8 mm)
        reached = closest_b <= 0.3 * self.st.scallop
        placed_off = closest_a > 0.3 * self.st.scallop
        if cut.kind == "flat" or len(done) > 1:
            reached &= ~placed_off
        axis_a = int(np.clip(np.rint((sa - ys[0]) / step), 0, ys.size - 1))
        ca = np.where(placed_off, axis_a, ca)
        inside = reached[None, :] & on & (~placed_off[None, :] | (who == len(done)))
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
        # where both axes stand off the part (a pass run off the outline, margin RIM) the
        # fine rows stay between the two contacts, as the coarse ones do: there a ball
        # pivots on the outline at the same row from every pass, and the rows just inside
        # (cut by the later passes) read as a cusp of slope x row step (sample 1 with the
        # rim at 0.01: 20 passes 0.01-0.06 mm apart before the first that reaches the
        # top). On the part the rows around the top are kept (sample 3's downhill corner),
        # and so are margin-0 programs'. So are a flat end's: it does not pivot (its bottom
        # reaches the same strip from every axis within R of it), and its contacts on the
        # strip beside the outline are a band whose nearest rows are not where the cusp is
        # (flat6 on sample 3 with the rim: 0.0558 left at y = 0.4 with them, 0.0485 without)
        ax, ay = self.along[cols_ok] * self.e1[0], self.along[cols_ok] * self.e1[1]
        off = (
            (self.st.margin > 0 and self.st.cutter.kind != "flat")
            & (self.sampler.part_distance(ax + sa * self.e2[0], ay + sa * self.e2[1]) > 1e-9)
            & (self.sampler.part_distance(ax + sb * self.e2[0], ay + sb * self.e2[1]) > 1e-9)
        )
        between = ~off[None, :] | (
            (S >= ys[lo[cols_ok]][None, :] - 1e-9) & (S <= ys[hi[cols_ok]][None, :] + 1e-9)
        )
        fine = np.where(onf & reach & between, above, -np.inf)
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


class PlacedRows:
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
        placed = False
        while self.merged < len(done):
            p = done[self.merged]
            j0 = max(int(np.ceil((p[0] - R) / self.step)), first)
            j1 = int(np.floor((p[0] + R) / self.step)) + 1
            self._hold(first, j1)
            env = self.probe.placed_envelope(p, self.step, j0, j1)
            sl = slice(j0 - self.k0, j1 - self.k0)
            lower = env < self.stock[sl]
            self.stock[sl] = np.where(lower, env, self.stock[sl])
            self.owner[sl] = np.where(lower, self.merged, self.owner[sl])
            self.last = (j0, env)
            self.merged += 1
            placed = True
        if placed:
            self.probe.forget_candidates()

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
