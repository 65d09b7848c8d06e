"""An expert dispatcher: deadline-aware, battery-aware, conflict-avoiding.

The rules an experienced vertiport dispatcher would apply with the information of the
observation, knowing that each eVTOL gets the controller's attention only once every ``N``
minutes (the round-robin), so every timing decision looks one turn ahead:

* **Conflicts.** A vehicle in transit that the conflict probe flags is told to avoid; others
  continue.
* **The charger is the scarce resource.** Landings go to the nearest free charging port, and
  a free charging port goes to the waiting vehicle with the least battery. A hovering vehicle
  that cannot land on one waits in a **holding pattern beside the charger**: it moves to the
  free hover spot nearest to a charging port, then on between that spot and the next nearest
  free one, on paths that keep clear of the ports. In the battery model a vehicle in motion
  spends the cruise drain per metre (under rules v1 0.125 %/m, 0.25 %/min at 2 m a minute) and
  one hovering in place 2 %/min, so the pattern cuts the drain of the wait, and the landing,
  when the charger frees, is a short one. It waits until the ATC's energy check rules waiting out, then lands
  on the nearest free port (a vehicle grounded on a pad is better than one that runs empty
  in the air).
* **Take-offs.** A vehicle takes off inside its on-time window once it has enough charge for a
  trip; on a charger it keeps charging until full or until its last on-time turn, unless
  another vehicle needs the charger. A vehicle short of charge stays (late beats stranded). On
  a normal port, where idling costs 4 %/min, it leaves before its window rather than idle
  below what the trip needs (bound: below 20 % more than that, so that it leaves before the
  others' windows crowd the airspace).
* **Repositioning.** A vehicle idling on a normal port moves to the nearest free charger,
  unless vehicles needier than it would run out without it.
* **Energy model.** Bound to an env (:meth:`DispatcherController.bind`, which the episode
  runners call), it adopts the env's drains and reserve, and a take-off needs the dearest trip
  from the vehicle's port, the reserve and two turns of hovering on return (at most 90 %);
  a vehicle on a charger that another one wants leaves 40 % above that, and at once when a
  waiting vehicle would otherwise run out within two turns. Its turn gaps are in minutes
  (the fleet size times the env's minutes per step, so a scenario that decides twice a minute
  has turns half as far apart). Unbound, it takes off at 90 %.

Three rules are options, off by default (tried on validation days, experiments/vertiport-capacity
and experiments/what-we-tried-rules-v0; none is part of the frozen dispatcher):

* **Departures first** (``yield_margin_pct``). Bound, a hovering vehicle that can afford to
  wait (after one more turn of hovering it would still hold the dearest take-off need and
  ``yield_margin_pct`` more) and whose landing stays on time at its next turn does not start
  a landing while a vehicle on a normal port is ready to take off (charged for it, in its
  window or at most a turn before): a landing across the field holds the departures under its
  path for as long as it flies, at 2 m a minute many minutes, and a vehicle held on a normal
  port idles at 4 %/min, twice the drain of hovering.
* **Behind other departures** (``departure_hold_min``). Bound, on a charging port a take-off
  also needs ``departure_hold_min`` minutes of hovering for each other vehicle departing: the
  separation check may hold it over its pad behind each of them, at the hover drain, while on
  the charger the wait costs nothing.
* **Low arrivals first** (``arrival_priority_pct``). With the holding pattern, a hovering
  vehicle yields a free charging port to a vehicle still arriving with less charge than
  ``arrival_priority_pct`` (and ``priority_margin_pct`` less than its own), as it does to a
  needier vehicle waiting aloft: the arriving vehicle will want the charger within a turn or
  two, and a vehicle that lands on it first keeps it until charged for a trip.

``DispatcherController(holding=False)`` is the earlier dispatcher without the holding pattern
and the priority (hovering vehicles wait in place, first come first served); the two are
compared in experiments/lost-vehicles-charger-rules-v0.

Every flight it chooses is one the action mask clears, so with the env's energy check
(``atc.energy_check``) it never starts a flight the battery cannot finish. Unbound, the energy
constants are the paper's (``cruise_drain_pct_per_m`` 0.5, unscaled); the decisions read only
the observation.
"""

from __future__ import annotations

import numpy as np

from agents.controllers.base import (
    ARRIVING, CHARGING_PORT, DEPARTING, HOVER_SPOT, HOVERING, NORMAL_PORT, ON_CHARGER, ON_PORT,
    TAXIING,
    Controller, Observation,
)
from marl_vertiport.sim.geometry import dot


#: Bound on the remembered holding spots (see :meth:`DispatcherController.holding_spot`).
_HOLDING_MEMO_MAX = 4096


def _segment_point_distance_m(a: np.ndarray, b: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Horizontal distance (m) from each of ``points`` ``(K, 2)`` to the segment ``a``-``b``
    (each ``(2,)``), shape ``(K,)``."""
    ab = b - a
    rel = points - a
    # Products added in plain arithmetic, not by BLAS (marl_vertiport/sim/geometry.py).
    along = rel[:, 0] * ab[0] + rel[:, 1] * ab[1]
    t = np.clip(along / max(dot(ab, ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


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
        holding: the holding pattern beside the charger and the neediest-first charger
            (``False``: hovering vehicles wait in place, the first to get a turn lands).
        priority_margin_pct: battery gap (percent) that makes a waiting vehicle yield a free
            charging port to a needier one.
        port_clearance_m: least horizontal distance (m) between a holding move's path and any
            port, so that it stays clear of the vehicles climbing from and descending to the
            ports (the separation minimum, 3 m, plus the vehicle size).
        return_wait_turns: bound (:meth:`bind`): turns of hovering on return, waiting for a
            charging port, that a take-off must have the charge for beyond the trip and the
            reserve.
        release_margin_pct: bound: a vehicle on a charging port that another vehicle wants
            takes off early once it has this much more than its take-off needs (at most
            ``early_release_battery_pct``).
        danger_turns: bound: a vehicle waiting for a charging port that would run out (less
            the reserve) within this many turns, hovering or idling, makes a vehicle on a
            charging port that can fly take off, and one on a normal port leave the charging
            port to it.
        ground_idle_drain_pct_per_min: battery a vehicle idling on a normal port loses per
            minute.
        leave_margin_pct: bound: a vehicle on a normal port takes off before its window once
            idling to the window would leave it less than this much above its take-off need
            (unbound: the need itself), so it leaves while the airspace is quieter than it will
            be when the others' windows open.
        yield_margin_pct: bound: a hovering vehicle yields the airspace to a vehicle ready to
            take off from a normal port while, after one more turn of hovering, it would still
            hold this much more than the dearest take-off need (``None``, the default: never).
        departure_hold_min: bound: minutes of hovering a take-off from a charging port needs
            for each other vehicle departing (0, the default: none).
        arrival_priority_pct: with the holding pattern, a hovering vehicle also yields the
            charger to an arriving vehicle with less than this charge (%) and
            ``priority_margin_pct`` less than its own (``None``, the default: only to vehicles
            waiting aloft).
    """

    name = "dispatcher"
    pure_act = True

    def __init__(self, trip_battery_pct: float = 90.0, hop_battery_pct: float = 12.0,
                 early_release_battery_pct: float = 95.0, on_time_tolerance_min: float = 5.0,
                 hover_drain_pct_per_min: float = 2.0, cruise_drain_pct_per_m: float = 0.5,
                 hover_altitude_m: float = 4.0, energy_reserve_pct: float = 5.0,
                 holding: bool = True, priority_margin_pct: float = 5.0,
                 port_clearance_m: float = 4.0, return_wait_turns: float = 2.0,
                 release_margin_pct: float = 40.0, danger_turns: float = 2.0,
                 ground_idle_drain_pct_per_min: float = 4.0,
                 leave_margin_pct: float = 20.0,
                 yield_margin_pct: float | None = None,
                 departure_hold_min: float = 0.0,
                 arrival_priority_pct: float | None = None) -> None:
        self.trip_battery_pct = trip_battery_pct
        self.hop_battery_pct = hop_battery_pct
        self.early_release_battery_pct = early_release_battery_pct
        self.tol = on_time_tolerance_min
        self.hover_drain_pct_per_min = hover_drain_pct_per_min
        self.cruise_drain_pct_per_m = cruise_drain_pct_per_m
        self.hover_altitude_m = hover_altitude_m
        self.energy_reserve_pct = energy_reserve_pct
        self.holding = holding
        self.priority_margin_pct = priority_margin_pct
        self.port_clearance_m = port_clearance_m
        self.return_wait_turns = return_wait_turns
        self.release_margin_pct = release_margin_pct
        self.danger_turns = danger_turns
        self.ground_idle_drain_pct_per_min = ground_idle_drain_pct_per_min
        self.leave_margin_pct = leave_margin_pct
        self.yield_margin_pct = yield_margin_pct
        self.departure_hold_min = departure_hold_min
        self.arrival_priority_pct = arrival_priority_pct
        #: Schedule minutes per step (bound: the env's; unbound, the paper's one minute).
        self.minutes_per_step = 1.0
        self._holding_memo: dict[tuple, int | None] = {}
        #: Per port, the charge a take-off from it needs (``None`` until :meth:`bind`).
        self._takeoff_need_pct: np.ndarray | None = None

    def bind(self, sim) -> None:
        """Adopt the energy model of the env whose simulator is ``sim``: its drains, its
        reserve, and per port the charge a take-off needs, the dearest trip from that port
        (``sim.energy.trip_pct``), the reserve, and ``return_wait_turns`` turns of hovering
        on return (a wait for a charger). An operator knows the fleet's energy model; the
        decisions still read only the observation. Unbound, the constructor's constants hold
        (the paper's drains, take-off at ``trip_battery_pct``)."""
        bat = sim.cfg.battery
        minutes = sim.cfg.schedule.minutes_per_step  # the battery's rates are per step
        self.minutes_per_step = minutes
        self.cruise_drain_pct_per_m = bat.cruise_pct_per_m
        self.hover_drain_pct_per_min = bat.hover_drain_pct / minutes
        self.ground_idle_drain_pct_per_min = bat.ground_idle_drain_pct / minutes
        self.energy_reserve_pct = sim.cfg.atc.energy_reserve_pct
        wait = self.return_wait_turns * sim.n * bat.hover_drain_pct
        need = sim.energy.trip_pct.max(axis=1) + self.energy_reserve_pct + wait
        self._takeoff_need_pct = np.minimum(need, self.trip_battery_pct)

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
    def _turn_gap(self, obs: Observation) -> float:
        """Minutes until this vehicle's next turn: the fleet size in steps, in round-robin
        order."""
        return len(obs.fleet("status")) * self.minutes_per_step

    @staticmethod
    def _holding(obs: Observation) -> np.ndarray:
        """Per vehicle, whether it moves between hover spots (taxiing to a hover spot), ``(N,)``."""
        status = obs.fleet("status").astype(int)
        node = obs.fleet("node").astype(int)
        to_node_type = obs.ports("type")[np.clip(node, 0, None)]
        return (status == TAXIING) & (node >= 0) & (to_node_type == HOVER_SPOT)

    def _waiting_aloft(self, obs: Observation) -> np.ndarray:
        """Per vehicle, whether it waits in the air for a landing: hovering, or (with the
        holding pattern) moving between hover spots, ``(N,)``."""
        hovering = obs.fleet("status").astype(int) == HOVERING
        return hovering | self._holding(obs) if self.holding else hovering

    def _charger_wanted(self, obs: Observation) -> bool:
        """Whether more other vehicles wait for a charging port than there are free ones:
        waiting aloft or arriving to land, or idling on a normal port short of charge for a
        trip."""
        status = obs.fleet("status").astype(int)
        battery = obs.fleet("battery_pct")
        others = np.arange(len(status)) != obs.me
        waiting = others & (self._waiting_aloft(obs) | (status == ARRIVING)
                            | ((status == ON_PORT) & (battery < self._fleet_need(obs))))
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
        need = self._takeoff_need(obs)
        can_fly = battery >= need and bool(obs.mask[obs.takeoff])
        if status == ON_CHARGER:
            wanted = self._charger_wanted(obs)
            if can_fly and (late or in_window and (battery >= 99.0 or last_chance or wanted)):
                return obs.takeoff
            if can_fly and wanted and battery >= self._release_pct(need):
                return obs.takeoff  # early, but the charger is what keeps the fleet flying
            if can_fly and self._bound and self._in_danger(obs).any():
                return obs.takeoff  # another vehicle runs out before it would get the charger
            return obs.stay
        # On a normal port: idling costs 4 %/min, so leave as soon as that is sensible.
        if can_fly and to_go <= self.tol:
            return obs.takeoff
        charger = self._nearest(obs, obs.reachable_nodes(CHARGING_PORT))
        if charger is not None and (battery >= self.hop_battery_pct or self._bound):
            danger = self._in_danger(obs)
            if not (danger.sum() >= obs.free_nodes(CHARGING_PORT).size
                    and (obs.fleet("battery_pct")[danger] < battery).all()):
                return obs.go_to(charger)  # unless needier vehicles run out without it
        # Idling to the window would leave too little for the trip, or little more: leave early
        # (early beats stranded on the pad, or held over it behind the others' departures).
        margin = self.leave_margin_pct if self._bound else 0.0
        if can_fly and battery - self.ground_idle_drain_pct_per_min * (
                to_go - self.tol + self._turn_gap(obs)) < need + margin:
            return obs.takeoff
        return obs.stay

    @property
    def _bound(self) -> bool:
        """Whether :meth:`bind` gave this dispatcher an env's energy model."""
        return self._takeoff_need_pct is not None

    def _in_danger(self, obs: Observation) -> np.ndarray:
        """Per other vehicle, whether it waits for a charging port (aloft, arriving, or idling
        on a normal port short of charge for a take-off) and would run out within
        ``danger_turns`` turns at its drain (hovering or idling), less the reserve, ``(N,)``."""
        status = obs.fleet("status").astype(int)
        battery = obs.fleet("battery_pct")
        others = np.arange(len(status)) != obs.me
        aloft = self._waiting_aloft(obs) | (status == ARRIVING)
        grounded = (status == ON_PORT) & (battery < self._fleet_need(obs))
        minutes = self.danger_turns * self._turn_gap(obs)
        left = battery - self.energy_reserve_pct - minutes * np.where(
            grounded, self.ground_idle_drain_pct_per_min, self.hover_drain_pct_per_min)
        return others & (aloft | grounded) & (left < 0.0)

    def _release_pct(self, need: float) -> float:
        """Charge at which a vehicle on a charging port that another vehicle wants takes off
        early."""
        if not self._bound:
            return self.early_release_battery_pct
        return min(self.early_release_battery_pct, need + self.release_margin_pct)

    def _fleet_need(self, obs: Observation) -> np.ndarray:
        """Per vehicle, the charge it needs to take off from the port it is on, ``(N,)``."""
        if not self._bound:
            return np.full(len(obs.fleet("node")), self.trip_battery_pct)
        node = obs.fleet("node").astype(int)
        ports = len(self._takeoff_need_pct)
        return np.where((node >= 0) & (node < ports),
                        self._takeoff_need_pct[np.clip(node, 0, ports - 1)], self.trip_battery_pct)

    def _takeoff_need(self, obs: Observation) -> float:
        """Charge (percent) the acting vehicle needs to take off from its port (bound, on a
        charging port: with ``departure_hold_min`` of hovering per other departing vehicle)."""
        if not self._bound:
            return self.trip_battery_pct
        need = float(self._takeoff_need_pct[int(obs.mine("node"))])
        if obs.status == ON_CHARGER and self.departure_hold_min > 0:
            # Others departing (the acting vehicle, on its charging port, is not among them).
            departing = int((obs.fleet("status").astype(int) == DEPARTING).sum())
            need = min(need + self.hover_drain_pct_per_min * self.departure_hold_min * departing,
                       99.0)
        return need

    def _yields_to_departures(self, obs: Observation) -> bool:
        """Whether the acting vehicle, hovering, lets a departure from a normal port go
        first (see "Departures first" in the module docstring)."""
        if not self._bound or self.yield_margin_pct is None or not obs.mask[obs.stay]:
            return False
        gap = self._turn_gap(obs)
        after_wait = obs.mine("battery_pct") - self.hover_drain_pct_per_min * gap
        if after_wait < float(self._takeoff_need_pct.max()) + self.yield_margin_pct:
            return False
        if obs.mine("minutes_to_schedule") - gap < -self.tol:
            return False  # the landing would be late at the next turn
        status = obs.fleet("status").astype(int)
        ready = ((status == ON_PORT) & (obs.fleet("minutes_to_schedule") <= self.tol + gap)
                 & (obs.fleet("battery_pct") >= self._fleet_need(obs)))
        return bool(ready.any())

    def _hovering(self, obs: Observation) -> int:
        if self._yields_to_departures(obs):
            return obs.stay
        chargers = obs.reachable_nodes(CHARGING_PORT)
        if self.holding and chargers.size and obs.mask[obs.stay]:
            others = np.arange(len(obs.fleet("status"))) != obs.me
            battery = obs.fleet("battery_pct")
            waiting = self._waiting_aloft(obs)
            if self.arrival_priority_pct is not None:  # and the low vehicles arriving
                waiting = waiting | ((obs.fleet("status").astype(int) == ARRIVING)
                                     & (battery < self.arrival_priority_pct))
            needier = others & waiting & (
                battery < obs.mine("battery_pct") - self.priority_margin_pct)
            if int(needier.sum()) >= chargers.size:
                chargers = chargers[:0]  # yield the charger to a needier vehicle
        if chargers.size:
            return obs.go_to(self._nearest(obs, chargers))
        if not obs.mask[obs.stay]:  # the ATC clears only landings: the last one it can make
            return obs.go_to(self._nearest(obs, obs.reachable_nodes(NORMAL_PORT)))
        if self.holding:
            spot = self.holding_spot(obs)
            if spot is not None:
                return obs.go_to(spot)
        chargers = np.flatnonzero(obs.ports("type") == CHARGING_PORT)
        need = float(self._landing_pct(obs, chargers).min()) + self.energy_reserve_pct
        after_wait = obs.mine("battery_pct") - self.hover_drain_pct_per_min * self._turn_gap(obs)
        if after_wait <= need:  # the next turn would be too late for a charger
            port = self._nearest(obs, obs.reachable_nodes(NORMAL_PORT))
            if port is not None:
                return obs.go_to(port)
        return obs.stay

    def holding_spot(self, obs: Observation) -> int | None:
        """The hover spot a hovering vehicle that cannot land on a charger moves to next in the
        holding pattern (``None``: none it may move to): of the free hover spots other than its
        own whose straight path from it keeps ``port_clearance_m`` from every port, the one
        nearest to a charging port.

        The answer depends only on the layout, the mask, the vehicle's node and position, and
        the same ones recur all day (a vehicle waits at a hover spot), so it is remembered: a
        cache of a pure function, bounded, that changes no answer."""
        key = (obs.ports("type").tobytes(), obs.ports("x_m").tobytes(), obs.ports("y_m").tobytes(),
               obs.mask.tobytes(), obs.mine("node"), obs.mine("x_m"), obs.mine("y_m"))
        memo = self._holding_memo
        if key not in memo:
            if len(memo) >= _HOLDING_MEMO_MAX:
                memo.clear()
            memo[key] = self._holding_spot(obs)
        return memo[key]

    def _holding_spot(self, obs: Observation) -> int | None:
        types = obs.ports("type")
        spots = np.flatnonzero(types == HOVER_SPOT)
        chargers = np.flatnonzero(types == CHARGING_PORT)
        if spots.size == 0 or chargers.size == 0:
            return None
        px, py = obs.ports("x_m"), obs.ports("y_m")
        to_charger_m = np.hypot(px[spots, None] - px[chargers][None],
                                py[spots, None] - py[chargers][None]).min(axis=1)
        allowed = (obs.mask[obs.go_to(0) + spots] == 1) & (spots != int(obs.mine("node")))
        ports_xy = np.column_stack([px, py])[types != HOVER_SPOT]
        here = np.array([obs.mine("x_m"), obs.mine("y_m")])
        for k in np.flatnonzero(allowed):  # keep clear of the ports' climbs and descents
            path_end = np.array([px[spots[k]], py[spots[k]]])
            if _segment_point_distance_m(here, path_end, ports_xy).min() < self.port_clearance_m:
                allowed[k] = False
        if not allowed.any():
            return None
        return int(spots[allowed][np.argmin(to_charger_m[allowed])])
