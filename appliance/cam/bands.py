"""The stepover planner on two cores: one planner from each end, meeting where they cross.

Placing passes is sequential (each candidate is measured against the passes before it), and
it is most of a finishing program's time. But a pass placed on a boundary can end the
passes below it (the planner lands its last pass on its far bound) and start the passes above
it: the same pass twice, kept once. So the part can be planned in two pieces at once.

Where to cut it is the question. Cut at a fixed place (equal areas of the footprint), the
two halves took 5.6 and 7.0 s on the daemon's demo scan: the work follows the map's detail,
which no cheap measure foresees. So the boundary is found as the planners go: the lower
planner works upwards from the first pass, the upper one (the same planner across -e2)
downwards from the last, each publishing its passes in shared memory with its clock, the
candidates it has measured so far (each costs about the same: a drop along the pass and its
scallop). The lower one decides: before each pass it looks at where the upper stood at the
same clock, and once the two have crossed they meet on the upper's last pass above the
lower's. The lower plans up to it; the upper ends there, dropping the passes it placed
beyond (it runs ahead as it can, up to LEAD candidates, and what it placed past the meeting
cost a core that would have idled).

The meeting depends on the passes and the clocks only, never on which process was faster:
the program is the same on every run. (A meeting where the fronts happened to be when they
looked moved with the machine's load: 140 to 150 passes on the demo scan.) Counted in passes
instead of candidates, the two waited for each other 0.2-0.5 s of their 4.4: the passes'
costs vary, the candidates' much less.

Each keeps the scallop within the request on its own; the lower planner's last pass is
measured without the upper one's cuts, which only lowers the real stock between them. Both
read one opening (opening.py), built first in halves of rows on the two cores.

The upper planner runs in this process and the lower in a forked worker. A planner that
ends (or fails) says so, and the other stops waiting for it; a worker killed before it
could is noticed from its process. Where forking is allowed is forks.py's business (the
processing child and the commands; never the daemon with its threads); elsewhere it plans
in one piece.
"""

from __future__ import annotations

import mmap
import os
import time

import numpy as np

from ..errors import InkSliceError
from ..forks import in_workers, workers
from .envelope import planner_opening
from .passplan import plan_passes

MIN_BAND_MM = 20.0  # parts narrower than two of these are planned in one piece
_WAIT_S = 0.0005  # a planner's poll while the other one places its pass
_MAX_PASSES = 100_000  # per planner: 0.01 mm steps over a metre
LEAD = 40  # candidates the upper planner may measure ahead of the lower


class Meeting:
    """The two planners' passes in memory both processes share: each pass's across position
    (along e2, the upper's too) and the candidates its planner had measured by then (its
    clock); how many passes each has placed, whether each has ended, where they met."""

    def __init__(self):
        n = 4 * _MAX_PASSES + 7
        self._mem = mmap.mmap(-1, n * 8)  # anonymous and shared: a fork sees the same pages
        v = np.frombuffer(self._mem, np.float64)
        self.lower_at, self.upper_at, self.lower_clock, self.upper_clock = (
            v[i * _MAX_PASSES : (i + 1) * _MAX_PASSES] for i in range(4)
        )
        rest = v[4 * _MAX_PASSES :]
        self.count = rest[0:2]  # passes placed: lower, upper
        self.ended = rest[2:4]  # lower, upper: 1 once it has ended (or failed)
        self.pid = rest[4:6]  # each planner's process (a killed one ends nothing)
        self.met = rest[6:7]  # the index of the upper's pass they met on; -1 until they have
        rest[:] = 0
        self.met[0] = -1

    def lower(self) -> _Lower:
        return _Lower(self)

    def upper(self) -> _Upper:
        return _Upper(self)


class _Side:
    def __init__(self, meeting: Meeting, which: int):
        self.m, self.which = meeting, which
        self.at = None  # where this side has met the other (own terms)
        self.drop = 0  # the upper's passes beyond the meeting, to be dropped
        meeting.pid[which] = os.getpid()

    def _publish(self, at, clock, s, measured) -> int:
        k = int(self.m.count[self.which])
        if k >= _MAX_PASSES:
            raise InkSliceError("finishing", f"more than {_MAX_PASSES} passes from one side")
        at[k], clock[k] = s, measured
        self.m.count[self.which] = k + 1  # written last: the other reads up to the count
        return k

    def _wait(self, until):
        """Poll until `until()` or the other side has ended (a killed one too)."""
        other, polls = 1 - self.which, 0
        while not until() and not self.m.ended[other]:
            time.sleep(_WAIT_S)
            polls += 1
            if polls % 200 == 0 and not _alive(int(self.m.pid[other]), polls * _WAIT_S):
                self.m.ended[other] = 1.0  # killed before its own `done`

    def done(self):
        self.m.ended[self.which] = 1.0


class _Lower(_Side):
    """The lower planner decides where they meet, from the upper's passes up to its own clock."""

    def __init__(self, meeting):
        super().__init__(meeting, 0)

    def end(self, sa, s1, measured, step_max):
        """Where to plan to now, asked before each pass with the pass placed last (sa), the
        candidates measured so far and the largest step the planner takes."""
        if self.at is not None:
            return self.at
        m = self.m
        self._publish(m.lower_at, m.lower_clock, sa, measured)
        n = int(m.count[1])
        behind = measured - m.upper_clock[n - 1] if n > 0 else -1
        if behind >= 0 and m.upper_at[n - 1] - sa > (behind + 1) * step_max:
            # the upper's clock has not got this far, and it cannot cross this pass by then:
            # every pass of its costs a candidate at least and moves at most step_max
            return s1
        # the upper's passes up to this clock: known once its clock has passed it
        self._wait(lambda: m.count[1] > 0 and m.upper_clock[int(m.count[1]) - 1] > measured)
        n = int(m.count[1])
        if n == 0 or m.upper_clock[n - 1] <= measured:
            return s1  # the upper ended before it got here: it failed, and its error is raised
        j = int(np.searchsorted(m.upper_clock[:n], measured, side="right")) - 1
        if j < 0 or m.upper_at[j] > sa:  # they have not crossed by this clock
            return s1
        # crossed (or touched): they meet on the upper's last pass above this one
        j = int(np.flatnonzero(m.upper_at[: j + 1] > sa)[-1])
        m.met[0] = j
        self.at = float(m.upper_at[j])
        return self.at


class _Upper(_Side):
    """The upper planner, mirrored (s' = -s): it runs ahead as it can (up to LEAD candidates),
    and ends on the pass the lower one met it on, dropping those it placed beyond."""

    def __init__(self, meeting):
        super().__init__(meeting, 1)

    def end(self, sa, s1, measured, step_max):
        if self.at is not None:
            return self.at
        m = self.m
        k = self._publish(m.upper_at, m.upper_clock, -sa, measured)
        self._wait(
            lambda: (
                m.met[0] >= 0
                or measured < LEAD
                or (m.count[0] > 0 and m.lower_clock[int(m.count[0]) - 1] > measured - LEAD)
            )
        )
        if m.met[0] < 0:
            return s1
        j = int(m.met[0])
        self.at, self.drop = -float(m.upper_at[j]), k - j
        return self.at


def _alive(pid: int, waited_s: float) -> bool:
    """Whether process pid runs (ended, a zombie: no). Pid 0: it has not begun; one that has
    not begun after a minute never will (killed between the fork and its first line)."""
    if pid == 0:
        return waited_s < 60.0
    try:
        with open(f"/proc/{pid}/stat") as f:  # the box is Linux (forks.py forks only there)
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:  # reaped
        return False


def plan_in_bands(sampler, st, e1, e2, t0, n, s0, s1):
    """plan_passes over [s0, s1]: from both ends at once on forked workers where allowed."""
    if workers() < 2 or s1 - s0 < 2 * MIN_BAND_MM:
        return plan_passes(sampler, st, e1, e2, t0, n, s0, s1)
    opening = planner_opening(sampler, st)
    meeting = Meeting()

    def side(which, e, a, b):
        me = (meeting.lower, meeting.upper)[which]()
        try:
            passes, tips = plan_passes(sampler, st, e1, e, t0, n, a, b, meet=me, opening=opening)
        finally:
            me.done()  # the other must not wait for a planner that has ended
        keep = len(passes) - me.drop
        return passes[:keep], tips[:keep]

    def upper():
        passes, tips = side(1, -e2, -s1, -s0)
        return -passes[::-1], tips[::-1]

    (high, high_tips), (low, low_tips) = in_workers([upper, lambda: side(0, e2, s0, s1)])
    if meeting.met[0] < 0 or low[-1] != high[0]:
        raise InkSliceError("finishing", "the two stepover planners did not meet (a bug: please report it)")
    return np.concatenate([low, high[1:]]), np.concatenate([low_tips, high_tips[1:]])
