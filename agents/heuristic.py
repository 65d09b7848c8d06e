"""An expert dispatcher: deadline-aware, battery-aware, conflict-avoiding.

The rules an experienced vertiport dispatcher would apply with the information of the
observation, knowing that each eVTOL gets the controller's attention only once every ``N``
minutes (the round-robin), so every timing decision looks one turn ahead:

* **Conflicts.** A vehicle in transit that the conflict probe flags is told to avoid; others
  continue.
* **The charger is the scarce resource.** Landings go to the nearest free charging port. A
  hovering vehicle keeps hovering (2 %/min) rather than landing on a normal port (4 %/min
  idle) as long as its battery, after one more turn of hovering, still covers the landing on a
  charging port; after that it lands on the nearest free port (a vehicle grounded on a pad is
  better than one that runs empty in the air).
* **Take-offs.** A vehicle takes off inside its on-time window once it has enough charge for a
  trip; on a charger it keeps charging until full or until its last on-time turn, unless
  another vehicle needs the charger. A vehicle short of charge stays (late beats stranded).
* **Repositioning.** A vehicle idling on a normal port moves to the nearest free charger.

Every flight it chooses is one the action mask clears, so with the env's energy check
(``atc.energy_check``) it never starts a flight the battery cannot finish. The energy constants
are the defaults of the shipped configs (``configs/env/paper.yaml``); the controller sees only
the observation.
"""

from __future__ import annotations

import numpy as np

from agents.base import (
    ARRIVING, CHARGING_PORT, HOVER_SPOT, HOVERING, NORMAL_PORT, ON_CHARGER, ON_PORT, Controller,
    Observation,
)


class DispatcherController(Controller):
    """Charger-centred, deadline-aware dispatching with conflict avoidance.

    Args:
        trip_battery_pct: charge needed to take off for a trip (a trip and the landing after
            it take about half of a full battery in the shipped layouts; the rest covers the
            wait for a charger on return).
        hop_battery_pct: least charge for a hop from a normal port to the charger.
        early_release_battery_pct: a vehicle this full releases a wanted charger by taking
            off, even before its window.
        on_time_tolerance_min: the schedule window half-width (paper: 5 minutes).
        hover_drain_pct_per_min: battery a hovering vehicle loses per minute.
        cruise_drain_pct_per_m: battery per metre flown.
        hover_altitude_m: altitude of the hover spots (a landing descends that far).
        energy_reserve_pct: the battery a landing must leave over (the env's
            ``atc.energy_reserve_pct``).
    """

    name = "heuristic"

    def __init__(self, trip_battery_pct: float = 90.0, hop_battery_pct: float = 12.0,
                 early_release_battery_pct: float = 95.0, on_time_tolerance_min: float = 5.0,
                 hover_drain_pct_per_min: float = 2.0, cruise_drain_pct_per_m: float = 0.5,
                 hover_altitude_m: float = 4.0, energy_reserve_pct: float = 5.0) -> None:
        self.trip_battery_pct = trip_battery_pct
        self.hop_battery_pct = hop_battery_pct
        self.early_release_battery_pct = early_release_battery_pct
        self.tol = on_time_tolerance_min
        self.hover_drain_pct_per_min = hover_drain_pct_per_min
        self.cruise_drain_pct_per_m = cruise_drain_pct_per_m
        self.hover_altitude_m = hover_altitude_m
        self.energy_reserve_pct = energy_reserve_pct

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
        """Whether more other vehicles wait for a charging port than there are free ones:
        hovering or arriving to land, or idling on a normal port short of charge for a trip."""
        status = obs.fleet("status").astype(int)
        battery = obs.fleet("battery_pct")
        others = np.arange(len(status)) != obs.me
        waiting = others & ((status == HOVERING) | (status == ARRIVING)
                            | ((status == ON_PORT) & (battery < self.trip_battery_pct)))
        return int(waiting.sum()) > obs.free_nodes(CHARGING_PORT).size

    def _nearest(self, obs: Observation, nodes: np.ndarray) -> int | None:
        """The node of ``nodes`` nearest to the acting vehicle (``None`` if there is none)."""
        if nodes.size == 0:
            return None
        return int(nodes[np.argmin(self._distance_m(obs, nodes))])

    @staticmethod
    def _distance_m(obs: Observation, nodes: np.ndarray) -> np.ndarray:
        """Horizontal distance (m) from the acting vehicle to each of ``nodes``."""
        dx = obs.ports("x_m")[nodes] - obs.mine("x_m")
        dy = obs.ports("y_m")[nodes] - obs.mine("y_m")
        return np.hypot(dx, dy)

    def _landing_pct(self, obs: Observation, nodes: np.ndarray) -> np.ndarray:
        """Estimated battery (percent) of a landing from the hover altitude on each of
        ``nodes``: across and down at the cruise drain, plus one partial step."""
        metres = self._distance_m(obs, nodes) + self.hover_altitude_m
        return self.cruise_drain_pct_per_m * metres + 1.0

    # ------------------------------------------------------------------ rules
    def _on_ground(self, obs: Observation, status: int) -> int:
        to_go = obs.mine("minutes_to_schedule")
        battery = obs.mine("battery_pct")
        in_window = -self.tol <= to_go <= self.tol
        late = to_go < -self.tol
        last_chance = to_go - self._turn_gap(obs) < -self.tol  # next turn falls after the window
        # A take-off the mask clears (with the energy check: one the battery can finish).
        can_fly = battery >= self.trip_battery_pct and bool(obs.mask[obs.takeoff])
        if status == ON_CHARGER:
            wanted = self._charger_wanted(obs)
            if can_fly and (late or in_window and (battery >= 99.0 or last_chance or wanted)):
                return obs.takeoff
            if can_fly and wanted and battery >= self.early_release_battery_pct:
                return obs.takeoff  # early, but the charger is what keeps the fleet flying
            return obs.stay
        # On a normal port: idling costs 4 %/min, so leave as soon as that is sensible.
        if can_fly and to_go <= self.tol:
            return obs.takeoff
        charger = self._nearest(obs, obs.reachable_nodes(CHARGING_PORT))
        if charger is not None and battery >= self.hop_battery_pct:
            return obs.go_to(charger)
        return obs.stay

    def _hovering(self, obs: Observation) -> int:
        charger = self._nearest(obs, obs.reachable_nodes(CHARGING_PORT))
        if charger is not None:
            return obs.go_to(charger)
        if not obs.mask[obs.stay]:  # the ATC clears only landings: the last one it can make
            return obs.go_to(self._nearest(obs, obs.reachable_nodes(NORMAL_PORT)))
        chargers = np.flatnonzero(obs.ports("type") == CHARGING_PORT)
        need = float(self._landing_pct(obs, chargers).min()) + self.energy_reserve_pct
        after_wait = obs.mine("battery_pct") - self.hover_drain_pct_per_min * self._turn_gap(obs)
        if after_wait <= need:  # the next turn would be too late for a charger
            port = self._nearest(obs, obs.reachable_nodes(NORMAL_PORT))
            if port is not None:
                return obs.go_to(port)
        return obs.stay
