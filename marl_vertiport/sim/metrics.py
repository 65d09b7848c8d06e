"""The episode metrics: what each one counts, its label and unit, and which way is better,
defined once for the simulator, the evaluation and the training logs.

The paper reports total reward, mean battery, good take-offs and landings, delay and collisions
(section IV); the rest are ours (docs/observations.md, section 10.2). ``min_separation_m`` is the
smallest centre distance of two vehicles in the airspace over the day (swept over each step; NaN
for a day with fewer than two), ``separation_loss_min`` the minutes in which some pair was in
loss of separation; ``trail_hold_min`` the vehicle-minutes in which a flight cleared behind a
departure held where it was, waiting for the departure's reservation to clear (rules v1,
``atc.trail_departures``; such a vehicle drains as it hovers); ``reserve_violations`` the
completed trips that touched down with a battery below ``battery.landing_reserve_pct``
(docs/energy.md). :class:`EpisodeMetrics` holds
an episode's running totals; its :meth:`~EpisodeMetrics.summary` has exactly the keys of
:data:`METRICS`, in that order, plus ``action_counts``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class MetricInfo:
    """How one metric is shown and read."""

    label: str
    """Short label with its unit, for tables and chart titles."""
    axis: str = "count per day"
    """Axis label of its chart."""
    better: int = 0
    """+1 higher is better, -1 lower is better, 0 neither (a count that describes, not judges)."""
    logged: bool = False
    """Logged per iteration in training (curves.csv, warmstart.csv, TensorBoard)."""


#: Every metric of an episode, in the order of the episode summary (and of the CSV columns).
METRICS: dict[str, MetricInfo] = {
    "steps": MetricInfo("steps", "steps"),
    "total_reward": MetricInfo("total reward", "reward per day", +1, True),
    "mean_battery_pct": MetricInfo("mean battery (%)", "battery (%)", +1, True),
    "good_takeoffs": MetricInfo("good take-offs", better=+1, logged=True),
    "good_landings": MetricInfo("good landings", better=+1, logged=True),
    "takeoffs": MetricInfo("take-offs"),
    "failed_takeoffs": MetricInfo("failed take-offs"),
    "landings": MetricInfo("landings"),
    "mean_delay_min": MetricInfo("mean delay (min)", "delay per eVTOL (min)", -1, True),
    # The paper's "collisions": predicted conflicts left unresolved (S = -5), not contacts.
    "collisions": MetricInfo("unresolved conflicts", "unresolved predicted conflicts per day",
                             better=-1, logged=True),
    "avoided_conflicts": MetricInfo("avoided conflicts"),
    "separation_losses": MetricInfo("separation losses", better=-1, logged=True),
    "min_separation_m": MetricInfo("min separation (m)", "metres", +1, True),
    "separation_loss_min": MetricInfo("loss of separation (min)", "minutes per day", -1, True),
    "trail_hold_min": MetricInfo("held behind departures (min)", "vehicle-minutes per day", -1),
    "contacts": MetricInfo("contacts", better=-1, logged=True),
    # The same count as stranded_air (a depleted battery is a vehicle lost in the air).
    "battery_depletions": MetricInfo("depletions (lost in the air)", better=-1, logged=True),
    "stranded_air": MetricInfo("lost in the air", better=-1, logged=True),
    "stranded_ground": MetricInfo("lost on the ground", better=-1, logged=True),
    "stranded": MetricInfo("vehicles lost", better=-1, logged=True),
    "reserve_violations": MetricInfo("landings below reserve", better=-1),
    "service_min_lost": MetricInfo("service lost (min)", "service lost (min)", -1, True),
    "completed_trips": MetricInfo("completed trips"),
}

#: The metrics training logs, in order (curves.csv and warmstart.csv columns, TensorBoard).
TRAINING_METRICS: tuple[str, ...] = tuple(k for k, m in METRICS.items() if m.logged)


@dataclass
class EpisodeMetrics:
    """Running totals of an episode; :meth:`summary` gives the paper's metrics and ours."""

    steps: int = 0
    total_reward: float = 0.0
    battery_sum: float = 0.0
    good_takeoffs: int = 0
    takeoffs: int = 0
    failed_takeoffs: int = 0
    good_landings: int = 0
    landings: int = 0
    completed_trips: int = 0
    collisions: int = 0
    avoided_conflicts: int = 0
    separation_losses: int = 0
    min_separation_m: float = math.inf
    separation_loss_min: float = 0.0
    trail_hold_min: float = 0.0
    contacts: int = 0
    battery_depletions: int = 0
    stranded_air: int = 0
    stranded_ground: int = 0
    reserve_violations: int = 0
    action_counts: np.ndarray | None = None

    def copy(self) -> "EpisodeMetrics":
        """An independent copy (the action counts copied too)."""
        counts = self.action_counts
        return dataclasses.replace(self, action_counts=None if counts is None else counts.copy())

    def summary(self, delay_min_per_vehicle: np.ndarray, service_min_lost: float = 0.0) -> dict[str, Any]:
        """The metrics (keys: :data:`METRICS`, then ``action_counts``); ``delay_min_per_vehicle``
        ``(N,)``; ``service_min_lost`` is the minutes from each lost vehicle's loss to now."""
        return {
            "steps": self.steps,
            "total_reward": float(self.total_reward),
            "mean_battery_pct": self.battery_sum / max(self.steps, 1),
            "good_takeoffs": self.good_takeoffs,
            "good_landings": self.good_landings,
            "takeoffs": self.takeoffs,
            "failed_takeoffs": self.failed_takeoffs,
            "landings": self.landings,
            "mean_delay_min": float(delay_min_per_vehicle.mean()),
            "collisions": self.collisions,
            "avoided_conflicts": self.avoided_conflicts,
            "separation_losses": self.separation_losses,
            "min_separation_m": (float(self.min_separation_m) if math.isfinite(self.min_separation_m)
                                 else math.nan),
            "separation_loss_min": float(self.separation_loss_min),
            "trail_hold_min": float(self.trail_hold_min),
            "contacts": self.contacts,
            "battery_depletions": self.battery_depletions,
            "stranded_air": self.stranded_air,
            "stranded_ground": self.stranded_ground,
            "stranded": self.stranded_air + self.stranded_ground,
            "reserve_violations": self.reserve_violations,
            "service_min_lost": float(service_min_lost),
            "completed_trips": self.completed_trips,
            "action_counts": self.action_counts.tolist() if self.action_counts is not None else [],
        }
