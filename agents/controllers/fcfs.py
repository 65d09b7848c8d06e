"""The paper's first-come-first-serve (FCFS) controller.

Two queues in request order. A vehicle requests landing when it arrives back at the vertiport
(arriving or hovering). A vehicle on the ground requests take-off once its scheduled take-off
time has come and it has at least 60 % of charge; until then it charges, moving to the charging
port when that is free. Only the vehicle at the head of a queue is served; every other vehicle
is skipped (it stays where it is), so a waiting vehicle sits on a normal port or a hover spot.
A landing goes to the charging port when it is free, else to a normal port. Vehicles in flight
continue; FCFS never uses the avoid action. It keeps to the action mask: a vehicle whose
take-off the env's energy check (``atc.energy_check``) does not clear withdraws its request, so
it cannot hold up the queue, and charges until the take-off is cleared; a move the check does
not clear is not taken.

(Reading the 60 % rule as part of the request keeps the queue from deadlocking: a head that
waits for the charger while a vehicle that is not the head sits on it would block forever.)
"""

from __future__ import annotations

import numpy as np

from agents.controllers.base import (
    ARRIVING, CHARGING_PORT, HOVERING, NORMAL_PORT, ON_CHARGER, ON_PORT, Controller, Observation,
)

#: Battery a vehicle must have before FCFS lets it take off (the paper's FCFS rule).
TAKEOFF_MIN_BATTERY_PCT = 60.0


class FCFSController(Controller):
    """First-come-first-serve ATC; its queues persist across the turns of one episode."""

    name = "fcfs"

    def __init__(self, takeoff_min_battery_pct: float = TAKEOFF_MIN_BATTERY_PCT) -> None:
        self.takeoff_min_battery_pct = takeoff_min_battery_pct
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.landing_queue: list[int] = []
        self.takeoff_queue: list[int] = []
        #: Vehicles whose take-off was not cleared at their last turn: no request from them.
        self.not_cleared: set[int] = set()

    def _update_queues(self, obs: Observation) -> None:
        status = obs.fleet("status").astype(int)
        wants_landing = (status == HOVERING) | (status == ARRIVING)
        on_ground = ((status == ON_PORT) | (status == ON_CHARGER))
        wants_takeoff = (on_ground & (obs.fleet("minutes_to_schedule") <= 0)
                         & (obs.fleet("battery_pct") >= self.takeoff_min_battery_pct))
        wants_takeoff[list(self.not_cleared)] = False
        # Served, gone or withdrawn: drop; new requests join at the back (ties in index order).
        self.landing_queue = [v for v in self.landing_queue if wants_landing[v]]
        self.takeoff_queue = [v for v in self.takeoff_queue if on_ground[v] and v not in self.not_cleared]
        for v in np.flatnonzero(wants_landing).tolist():
            if v not in self.landing_queue:
                self.landing_queue.append(v)
        for v in np.flatnonzero(wants_takeoff).tolist():
            if v not in self.takeoff_queue:
                self.takeoff_queue.append(v)

    def act(self, observation: dict) -> int:
        obs = Observation(observation)
        me, status, mask = obs.me, obs.status, obs.mask
        if status in (ON_PORT, ON_CHARGER) and not mask[obs.takeoff]:
            self.not_cleared.add(me)
        else:
            self.not_cleared.discard(me)
        self._update_queues(obs)
        if status == HOVERING:
            if self.landing_queue[:1] != [me] and mask[obs.stay]:
                return obs.stay  # (the ATC lets a vehicle low on battery land out of turn)
            for node_type in (CHARGING_PORT, NORMAL_PORT):
                free = obs.reachable_nodes(node_type)
                if free.size:
                    return obs.go_to(free[0])
            return obs.stay
        if status in (ON_PORT, ON_CHARGER):
            if self.takeoff_queue[:1] == [me]:
                return obs.takeoff
            short = obs.mine("battery_pct") < self.takeoff_min_battery_pct or me in self.not_cleared
            if me not in self.takeoff_queue and short:
                chargers = obs.reachable_nodes(CHARGING_PORT)
                if status == ON_PORT and chargers.size:
                    return obs.go_to(chargers[0])
            return obs.stay
        # In flight, away, holding or out of service: the only sensible choice without a plan.
        return obs.continue_ if mask[obs.continue_] else obs.stay
