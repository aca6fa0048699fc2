"""An ETA that settles instead of jumping.

Printer UIs are mocked for estimates that leap about. The daemon reports its
own `eta_s`; what the operator sees is built here from what is observable,
levels done over time, so it behaves the same whatever the daemon's estimate
does:

1. per-level time: an exponentially weighted average (alpha = 0.3) of the time
   between successive level completions; a completion that covers several
   levels at once (a missed poll) counts as that many levels of equal time.
2. raw estimate = levels left x per-level time + the processing time the daemon
   expects (eta_processing_s, learned from this box's past jobs: daemon/eta.py).
3. shown estimate: between updates it counts down with the clock; at an update
   it moves only 30 % of the way towards the raw estimate, and never by more
   than max(3 s, 10 %) of the shown value in one update. So a single slow
   level does not push the estimate up by minutes, and a good run converges
   within a few levels. Before the first level completes the daemon's figure
   (if any) is shown as is, and so is its processing figure when processing
   starts (a new phase is news, not jitter).
"""

from __future__ import annotations

import threading
import time

ALPHA = 0.3
BLEND = 0.3
MIN_STEP_S = 3.0
MAX_STEP_FRACTION = 0.10


class EtaSmoother:
    def __init__(self, clock=time.monotonic):
        self.clock = clock
        self._lock = threading.Lock()
        self._reset(None)

    def _reset(self, job_id):
        self.job_id = job_id
        self.last_done = None
        self.last_t = None
        self.per_level = None
        self.shown = None
        self.shown_t = None
        self.phase = None

    def update(self, state: dict) -> float | None:
        """Feed a daemon state dict; returns the ETA in seconds to show (None if unknown)."""
        with self._lock:
            now = self.clock()
            st = state.get("state")
            if st not in ("homing", "scanning", "processing"):
                if st == "done":
                    self.shown = 0.0
                    return 0.0
                self._reset(state.get("job_id"))
                return None
            if state.get("job_id") != self.job_id:
                self._reset(state.get("job_id"))
            done = int(state.get("levels_done") or 0)
            total = int(state.get("levels_total") or 0)
            daemon_eta = state.get("eta_s")
            changed = phase_changed = st != self.phase
            if changed and st == "scanning":
                self.last_t = now  # homing time is not a level's time
            self.phase = st
            if self.last_done is None:
                self.last_done, self.last_t = done, now
                changed = True
            elif done > self.last_done:
                changed = True
                dt = (now - self.last_t) / (done - self.last_done)
                self.per_level = dt if self.per_level is None else ALPHA * dt + (1 - ALPHA) * self.per_level
                self.last_done, self.last_t = done, now
            elif done < self.last_done:  # resumed from an earlier level
                self.last_done, self.last_t = done, now
                changed = True

            if st == "processing" and daemon_eta is None:
                self.shown = None  # a box with no finished job yet: "processing", not "0 s"
                return None
            if self.per_level is None:
                raw = float(daemon_eta) if daemon_eta is not None else None
                if raw is None:
                    return None
                if changed or self.shown is None:
                    self.shown, self.shown_t = raw, now
                return round(max(0.0, self.shown - (now - self.shown_t)), 1)
            counted = max(0.0, self.shown - (now - self.shown_t)) if self.shown is not None else None
            if not changed and counted is not None:
                # between level completions the estimate just counts down, however often it is asked
                return round(counted, 1)
            left = max(0, total - done)
            raw = left * self.per_level + float(state.get("eta_processing_s") or 0.0)
            if st == "processing":
                raw = float(daemon_eta)
                if phase_changed:
                    self.shown, self.shown_t = raw, now
                    return round(raw, 1)
            if counted is None:
                counted = raw
            step = BLEND * (raw - counted)
            bound = max(MIN_STEP_S, MAX_STEP_FRACTION * counted)
            step = max(-bound, min(bound, step))
            self.shown, self.shown_t = max(0.0, counted + step), now
            return round(self.shown, 1)
