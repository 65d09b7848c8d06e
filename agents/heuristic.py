"""An expert dispatcher: deadline-aware, battery-aware, conflict-avoiding.

The rules an experienced vertiport dispatcher would apply with the information of the
observation, knowing that each eVTOL gets the controller's attention only once every ``N``
minutes (the round-robin), so every timing decision looks one turn ahead:

* **Conflicts.** A vehicle in transit that the conflict probe flags is told to avoid; others
  continue.
* **The charger is the scarce resource.** Landings go to a free charging port. A hovering
  vehicle keeps hovering (2 %/min) rather than landing on a normal port (4 %/min idle) while it
  can still land on time at its next turn; at its last on-time turn, or when its battery runs
  low, it lands on whatever is free.
* **Take-offs.** A vehicle takes off inside its on-time window once it has enough charge for a
  trip; on the charger it keeps charging until full or until its last on-time turn, unless
  another vehicle needs the charger. A vehicle short of charge stays (late beats stranded).
* **Repositioning.** A vehicle idling on a normal port moves to a free charger when its next
  take-off is far enough away for the move to pay off, or when it cannot make a trip otherwise.
"""

from __future__ import annotations

import numpy as np

from agents.base import (
    ARRIVING, CHARGING_PORT, HOVERING, NORMAL_PORT, ON_CHARGER, ON_PORT, Controller, Observation,
)


class DispatcherController(Controller):
    """Charger-centred, deadline-aware dispatching with conflict avoidance.

    Args:
        trip_battery_pct: charge needed to take off for a trip, hover while waiting for the
            charger, and land with margin.
        reserve_battery_pct: a hovering vehicle at or below this lands on any free port (a
            landing costs about 10 %).
        hop_battery_pct: least charge for a hop from a normal port to the charger.
        early_release_battery_pct: a vehicle this full releases a wanted charger by taking
            off, even before its window.
        on_time_tolerance_min: the schedule window half-width (paper: 5 minutes).
    """

    name = "heuristic"

    def __init__(self, trip_battery_pct: float = 80.0, reserve_battery_pct: float = 24.0,
                 hop_battery_pct: float = 12.0, early_release_battery_pct: float = 95.0,
                 on_time_tolerance_min: float = 5.0) -> None:
        self.trip_battery_pct = trip_battery_pct
        self.reserve_battery_pct = reserve_battery_pct
        self.hop_battery_pct = hop_battery_pct
        self.early_release_battery_pct = early_release_battery_pct
        self.tol = on_time_tolerance_min

    def act(self, observation: dict) -> int:
        obs = Observation(observation)
        status = obs.status
        if status in (ON_PORT, ON_CHARGER):
            return self._on_ground(obs, status)
        if status == HOVERING:
            return self._hovering(obs)
        if obs.mask[obs.avoid] and obs.mine("conflict") > 0:
            return obs.avoid
        return obs.continue_ if obs.mask[obs.continue_] else obs.stay

    # ------------------------------------------------------------------ helpers
    def _turn_gap(self, obs: Observation) -> int:
        """Minutes until this vehicle's next turn (the fleet size, in round-robin order)."""
        return len(obs.fleet("status"))

    def _charger_wanted(self, obs: Observation) -> bool:
        """Whether another vehicle is waiting for the charger: hovering or arriving to land,
        or idling on a normal port short of charge for a trip."""
        status = obs.fleet("status").astype(int)
        battery = obs.fleet("battery_pct")
        others = np.arange(len(status)) != obs.me
        waiting = others & ((status == HOVERING) | (status == ARRIVING))
        short = others & (status == ON_PORT) & (battery < self.trip_battery_pct)
        return bool(waiting.any() or short.any())

    # ------------------------------------------------------------------ rules
    def _on_ground(self, obs: Observation, status: int) -> int:
        to_go = obs.mine("minutes_to_schedule")
        battery = obs.mine("battery_pct")
        in_window = -self.tol <= to_go <= self.tol
        late = to_go < -self.tol
        last_chance = to_go - self._turn_gap(obs) < -self.tol  # next turn falls after the window
        can_fly = battery >= self.trip_battery_pct
        if status == ON_CHARGER:
            wanted = self._charger_wanted(obs)
            if can_fly and (late or in_window and (battery >= 99.0 or last_chance or wanted)):
                return obs.takeoff
            if wanted and battery >= self.early_release_battery_pct:
                return obs.takeoff  # early, but the charger is what keeps the fleet flying
            return obs.stay
        # On a normal port: idling costs 4 %/min, so leave as soon as that is sensible.
        if can_fly and to_go <= self.tol:
            return obs.takeoff
        chargers = obs.free_nodes(CHARGING_PORT)
        if chargers.size and battery >= self.hop_battery_pct:
            return obs.go_to(chargers[0])
        return obs.stay

    def _hovering(self, obs: Observation) -> int:
        chargers = obs.free_nodes(CHARGING_PORT)
        if chargers.size:
            return obs.go_to(chargers[0])
        # Hovering (2 %/min) is cheaper than idling on a normal port (4 %/min): keep waiting
        # for the charger unless the battery runs low.
        if obs.mine("battery_pct") <= self.reserve_battery_pct:
            ports = obs.free_nodes(NORMAL_PORT)
            if ports.size:
                return obs.go_to(ports[0])
        return obs.stay
