"""Flight plans, schedule windows and delays (paper, section II-A; docs/environment.md,
section 2.4).

Each vehicle has at most one pending operation with a scheduled minute ``t``: a take-off when on
the ground, a landing when back at the vertiport.

* at the start of a day a vehicle on a port has a take-off at a minute drawn uniformly from
  ``initial_takeoff_min`` (5 .. 20); one at a hover spot has a landing at ``landing_window_min``
  (15);
* re-entering the airspace in the step that ends at minute ``m``: a landing at
  ``m + landing_window_min``;
* touching down after a landing clearance, at the end of minute ``m``: a take-off at ``m + u``,
  ``u`` drawn uniformly from ``takeoff_after_landing_min`` (10 .. 20).

With the tolerance ``tol`` (``on_time_tolerance_min``, 5) and ``r = now - t``: the schedule
status is *early* (-1) when a take-off is pending and ``r < -tol``, *delayed* (1) when an
operation is pending and ``r > tol``, else *on time* (0); the delay is ``r`` when an operation
is pending and ``r > tol``, else 0. An operation completed (or dropped) more than ``tol`` late
adds its lateness to the vehicle's delay total.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from marl_vertiport.config import ScheduleConfig
from marl_vertiport.sim.schema import DELAYED, EARLY, NO_OPERATION, ON_TIME, PENDING_TAKEOFF


class FlightSchedule:
    """The schedule's draws and windows, and the delay and status of a pending operation."""

    def __init__(self, schedule: ScheduleConfig) -> None:
        self.cfg = schedule
        self.tolerance_min = schedule.on_time_tolerance_min

    # ------------------------------------------------------------------ plans
    def initial_takeoffs_min(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Scheduled minutes of the first take-offs, ``(n,)`` ints (one draw of ``n``)."""
        lo, hi = self.cfg.initial_takeoff_min
        return rng.integers(lo, hi + 1, size=n)

    def first_landing_min(self) -> float:
        """Scheduled minute of the landing of a vehicle that starts the day at a hover spot."""
        return self.cfg.landing_window_min

    def landing_min(self, end_min: float) -> float:
        """Scheduled minute of the landing of a vehicle that re-enters the airspace in the step
        ending at ``end_min``."""
        return end_min + self.cfg.landing_window_min

    def takeoff_after_landing_min(self, rng: np.random.Generator, end_min: float) -> float:
        """Scheduled minute of the take-off after a touchdown in the step ending at ``end_min``."""
        lo, hi = self.cfg.takeoff_after_landing_min
        return end_min + int(rng.integers(lo, hi + 1))

    # ------------------------------------------------------------------ lateness
    def lateness_min(self, now_min: float, scheduled_min: float) -> float:
        """What an operation done (or dropped) at ``now_min`` adds to the delay total: its
        lateness when beyond the tolerance, else 0."""
        late = now_min - scheduled_min
        return late if late > self.tolerance_min else 0.0

    def delays_min(self, minute: float, pending_time: np.ndarray, pending_kind: Sequence[int],
                   out: np.ndarray) -> list[float]:
        """Per vehicle, the delay now (minutes), ``(N,)``; ``out`` receives ``minute -
        pending_time``, the minutes since each scheduled time."""
        tol = self.tolerance_min
        rel = np.subtract(minute, pending_time, out=out).tolist()
        # r * False is r * 0.0: -0.0 while an operation is not yet due, as the features show.
        return [r * (r > tol and k != NO_OPERATION) for r, k in zip(rel, pending_kind)]

    def status_code(self, since_min: float, pending_kind: int) -> int:
        """Schedule status of one vehicle: ``since_min`` minutes after its scheduled time."""
        if since_min > self.tolerance_min and pending_kind != NO_OPERATION:
            return DELAYED
        if since_min < -self.tolerance_min and pending_kind == PENDING_TAKEOFF:
            return EARLY
        return ON_TIME

    def status_codes(self, minute: float, pending_time: np.ndarray, pending_kind: np.ndarray
                     ) -> np.ndarray:
        """Schedule status of every vehicle, ``(N,)`` ints."""
        tol = self.tolerance_min
        rel = minute - pending_time
        early = (rel < -tol) & (pending_kind == PENDING_TAKEOFF)
        delayed = (rel > tol) & (pending_kind != NO_OPERATION)
        return delayed.astype(np.int64) * DELAYED + early.astype(np.int64) * EARLY
