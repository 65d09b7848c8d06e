"""The vertiport simulator: the state of the day and the order of a step.

This module imports no RL or deep-learning library. The PettingZoo AEC env and the Gymnasium
env are thin translations of :class:`VertiportSim`; both call :meth:`VertiportSim.step` with
the action of the vehicle whose turn it is.

A step (``schedule.minutes_per_step`` of schedule time, one minute by default) follows the
paper's section II:

1. the ATC's instruction to the acting eVTOL is checked against its mask and applied (a
   misread may replace it, :mod:`~marl_vertiport.sim.uncertainty`); a take-off or landing
   scores its term of the reward and completes the pending operation
   (:mod:`~marl_vertiport.sim.reward`, :mod:`~marl_vertiport.sim.schedule`);
2. every vehicle moves for ``flight_seconds_per_step`` of flight, pybullet inside the airspace
   and a kinematic model outside it (:mod:`~marl_vertiport.sim.physics`), with wind gusts;
3. separation flown and contacts are measured (:mod:`~marl_vertiport.sim.safety`), arrivals
   and touchdowns processed, new flight plans drawn;
4. batteries drain or charge (:mod:`~marl_vertiport.sim.battery`), with charger failures;
   vehicles depleted in the air or stranded on the ground are counted as lost;
5. the clock advances, delays are updated, and the acting eVTOL's reward (eq. 2) is summed;
6. the conflict probe runs for the next state, the next eVTOL in round-robin order gets the
   turn, and observation noise is drawn.

The vocabulary (statuses, features, actions) is :mod:`~marl_vertiport.sim.schema`; the metrics
are :mod:`~marl_vertiport.sim.metrics`.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from marl_vertiport.config import EnvConfig
from marl_vertiport.sim.energy import FlightEnergy, local_route
from marl_vertiport.sim.battery import BatteryModel
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT, Layout
from marl_vertiport.sim.metrics import EpisodeMetrics
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, EVTOL_FEATURES, HOVERING, LEADING_ACTIONS, NO_OPERATION,
    ON_CHARGER, ON_PORT, OUT_OF_SERVICE, PENDING_LANDING, PENDING_TAKEOFF, SELF_FEATURES,
    STATE_EXTRA_FEATURES, STATE_PORT_FEATURES, STATUS_NAMES, TAXIING, ActionLayout, _IS_SELF,
    format_actions,
)
from marl_vertiport.sim.physics import FlightPhysics
from marl_vertiport.sim.reward import RewardModel
from marl_vertiport.sim.safety import (
    conflicting_pairs, planned_velocity, swept_distances_m,
)
from marl_vertiport.sim.schedule import FlightSchedule
from marl_vertiport.sim.uncertainty import Uncertainty

#: Index of the first node action ("go to node 0"): the action layout of sim/schema.py.
_NODES = LEADING_ACTIONS
# Per status code (indexed by a Python int on hot paths).
_AIRBORNE = (False, False, True, True, True, True, True, False)
_IN_TRANSIT_INSIDE = (False, False, False, True, True, False, True, False)

_DEFLECTION_TOL_M = 1e-4  # engine position vs commanded motion; integration error is ~1e-12

_SHARED = frozenset({int, float, bool, str, type(None)})


def _copied(value: Any) -> Any:
    """A copy of one value of the episode state, as deep as :func:`copy.deepcopy` would make it
    but faster on the state's own types: arrays, lists, dicts and sets of them are copied,
    immutable values (numbers, strings, tuples of numbers in sets) are shared; the metrics are
    copied by their own method and a generator by its state; any other value is deep-copied."""
    kind = type(value)
    if kind is np.ndarray:
        return value.copy()
    if kind in _SHARED:
        return value
    if kind is list:
        return [_copied(x) for x in value]
    if kind is dict:
        return {k: _copied(x) for k, x in value.items()}
    if kind is set:  # of hashable, so immutable, members: vehicle pairs, vehicle indices
        return set(value)
    if kind is EpisodeMetrics:
        return value.copy()
    if kind is np.random.Generator:  # the same state, so the same draws from here on
        bits = value.bit_generator
        twin = np.random.Generator(type(bits)(0))
        twin.bit_generator.state = bits.state
        return twin
    return copy.deepcopy(value)


class IllegalActionError(ValueError):
    """An action that is out of range, of the wrong type, or masked out."""


class VertiportSim:
    """One vertiport, its fleet, and the round-robin ATC turn.

    Args:
        config: validated environment config.
        gui: open pybullet's GUI (``render_mode="human"``).
    """

    def __init__(self, config: EnvConfig, gui: bool = False) -> None:
        self.cfg = config
        self.layout = Layout.from_config(config)
        self.actions = ActionLayout(self.layout.n_nodes)
        self.n = config.fleet_size
        fl = config.flight
        self.physics = FlightPhysics(self.n, fl.flight_seconds_per_step, fl.physics_rate_hz,
                                     fl.vehicle_size_m, fl.vehicle_height_m, fl.vehicle_mass_kg,
                                     gui=gui)
        self.dt_s = fl.flight_seconds_per_step
        self.minutes_per_step = config.schedule.minutes_per_step
        self.step_len_m = fl.cruise_speed_mps * fl.flight_seconds_per_step
        self.park_z_m = fl.vehicle_height_m / 2.0
        # Largest centre distance at which two boxes can touch (corner to corner), plus slack.
        self._touch_m = float(np.sqrt(2 * fl.vehicle_size_m ** 2 + fl.vehicle_height_m ** 2)) + 0.05
        # Within this distance two bodies may be a pair the engine checks for contact (their
        # boxes plus its margins overlap): a metre of slack over touching.
        self._near_m = self._touch_m + 1.0
        self.battery_model = BatteryModel(config.battery, _AIRBORNE, ON_PORT, ON_CHARGER)
        self.reward_model = RewardModel(config.reward, config.schedule)
        self.schedule = FlightSchedule(config.schedule)
        self.uncertainty = Uncertainty(config.uncertainty)
        lay = self.layout
        self._port_static = np.zeros((lay.n_nodes, 4), dtype=np.float32)
        self._port_static[:, 1] = lay.node_type
        self._port_static[:, 2:] = lay.node_xy_m
        self._node_pos = np.column_stack([lay.node_xy_m, lay.node_z_m])
        self._is_port = lay.node_type != HOVER_SPOT
        self._charging_nodes = np.flatnonzero(lay.node_type == CHARGING_PORT)
        self._charging_node_list = self._charging_nodes.tolist()
        self._agent_names = tuple(f"evtol_{i}" for i in range(self.n))
        self._fixed_masks = self._status_masks()
        # By status code: the action of a fixed mask with one legal action, -1 for a fixed mask
        # with several, None where the mask depends on the state.
        self._fixed_single = tuple(
            None if m is None else int(np.flatnonzero(m)[0]) if m.sum() == 1 else -1
            for m in self._fixed_masks)
        self.energy = FlightEnergy(config, self.layout)
        # Battery a hovering vehicle spends until its next turn (at most a full round).
        self._hold_pct = config.battery.hover_drain_pct * self.n
        # Everything set so far is fixed for the env's life; what follows is episode state,
        # which snapshot() copies.
        self._static_keys = frozenset(self.__dict__) | {"_static_keys"}
        self.rng = np.random.default_rng(0)
        self._allocate()

    # ================================================================== episode state
    def _allocate(self) -> None:
        n, lay = self.n, self.layout
        self.pos = np.zeros((n, 3))
        self.prev_pos = np.zeros((n, 3))
        self.cmd_vel = np.zeros((n, 3))
        self.target = np.zeros((n, 3))
        self.has_target = np.zeros(n, dtype=bool)
        self.routes: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.status = np.zeros(n, dtype=np.int64)
        self.battery = np.zeros(n)
        self.node = np.full(n, -1, dtype=np.int64)
        self.node_occupant = np.full(lay.n_nodes, -1, dtype=np.int64)
        self.leg_alt = np.zeros(n)
        self.avoid_layer = np.full(n, -1, dtype=np.int64)
        self.dest = np.zeros(n, dtype=np.int64)
        self.returning = np.zeros(n, dtype=bool)
        self.landing_cleared = np.zeros(n, dtype=bool)
        self.pending_kind = np.zeros(n, dtype=np.int64)
        self.pending_time = np.zeros(n)
        self.delay = np.zeros(n)
        self.completed_delay = np.zeros(n)
        self.sep_state: set[tuple[int, int]] = set()
        self.contact_state: set[tuple[int, int]] = set()
        self._moved: list[int] = []
        self._moved_m: list[float] = []
        self._deflected: list[int] = []
        self._any_cmd_vel = False
        self._holding: set[int] = set()
        self._rel_min = np.zeros(n)  # minutes since the pending operation's scheduled time
        self.plan_vel_xy = np.zeros((n, 2))
        self.conflict = np.zeros(n, dtype=bool)
        self._any_conflict_probe = False  # whether the last probe set a velocity or a flag
        self.obs_xy = np.zeros((n, 2))
        self.lost = np.zeros(n, dtype=bool)  # stranded: in the air or on the ground for good
        self.lost_min = np.zeros(n)  # minute at the end of the step in which it was lost

    def reset(self, rng: np.random.Generator) -> None:
        """Start a new day: vehicles placed on random ports (then hover spots), full batteries,
        first flight plans drawn; all from ``rng``."""
        self.rng = rng
        cfg, lay, n = self.cfg, self.layout, self.n
        self._allocate()
        self.minute = 0.0
        self.step_count = 0
        self.battery[:] = cfg.battery.initial_pct
        ports = rng.permutation(lay.n_ports)
        hovers = lay.n_ports + rng.permutation(lay.n_hover)
        placement = np.concatenate([ports, hovers])[:n]
        order = rng.permutation(n)
        takeoff_offsets = self.schedule.initial_takeoffs_min(rng, n)
        dests = rng.integers(0, len(lay.destination_xy_m), size=n)
        for v, node in zip(order.tolist(), placement.tolist()):
            self._occupy(v, node)
            self.pos[v] = self._node_pos[node]
            self.physics.make_static(v, self.pos[v])
            if self._is_port[node]:
                self.status[v] = ON_CHARGER if lay.node_type[node] == CHARGING_PORT else ON_PORT
                self.pending_kind[v] = PENDING_TAKEOFF
                self.pending_time[v] = takeoff_offsets[v]
            else:
                # A vehicle that starts at a hover spot has just arrived and waits to land.
                self.status[v] = HOVERING
                self.pending_kind[v] = PENDING_LANDING
                self.pending_time[v] = self.schedule.first_landing_min()
            self.dest[v] = dests[v]
        self.prev_pos[:] = self.pos
        self.physics.forget_contacts()  # nothing of the previous day's contacts carries over
        self._update_delays()
        self._refresh_conflicts()
        self.metrics = EpisodeMetrics(action_counts=np.zeros(self.actions.n, dtype=np.int64))
        self.acting = 0
        self._choose_actor(first=True)
        self._draw_observation_noise()
        self._mask_cache: dict[int, np.ndarray] = {}
        self._evtol_cache: np.ndarray | None = None
        self._port_cache: np.ndarray | None = None
        self.last_info: dict[str, Any] = {}

    # ================================================================== snapshots
    def snapshot(self) -> dict[str, Any]:
        """A deep copy of the episode state (vehicles, plans, clock, metrics, generator, and
        each engine body's mode and position), for planners that look ahead by simulating.

        The engine needs no more than that: a dynamic body's velocity is set at the start of
        every step, and bodies carry no other state between steps.
        """
        state = {k: _copied(v) for k, v in self.__dict__.items() if k not in self._static_keys}
        state["_physics"] = self.physics.body_states()
        return state

    def restore(self, state: dict[str, Any]) -> None:
        """Put this sim in the episode state ``state`` taken by :meth:`snapshot` of this sim or of
        another sim built from the same config (the snapshot itself is not changed)."""
        for k, v in state.items():
            if k != "_physics":
                setattr(self, k, _copied(v))
        self.physics.set_body_states(state["_physics"])
        if not self.uncertainty.noisy_observations:
            self.obs_xy = self.pos[:, :2]  # a view of the positions, as after a step

    # ================================================================== bookkeeping helpers
    def _occupy(self, v: int, node: int) -> None:
        self.node[v] = node
        self.node_occupant[node] = v

    def _release(self, v: int) -> None:
        node = self.node[v]
        if node >= 0 and self.node_occupant[node] == v:
            self.node_occupant[node] = -1
        self.node[v] = -1

    def _set_route(self, v: int, waypoints: list[np.ndarray], leg_alt_m: float) -> None:
        self.target[v] = waypoints[0]
        self.routes[v] = list(waypoints[1:])
        self.has_target[v] = True
        self.leg_alt[v] = leg_alt_m

    def _local_route(self, v: int, node: int) -> list[np.ndarray]:
        """Route at hover altitude from the vehicle to vertiport node ``node``."""
        return local_route(self.pos[v], self._node_pos[node], self.cfg.flight.hover_altitude_m)

    # ================================================================== masks
    def action_mask(self, v: int) -> np.ndarray:
        """Legal actions of vehicle ``v`` now, int8 of shape ``(A,)``, 1 = legal; never empty."""
        cached = self._mask_cache.get(v)
        if cached is not None:
            return cached
        s = self.status.item(v)
        mask = self._fixed_masks[s]
        if mask is None:  # on the ground or hovering: the free nodes it may go to
            acts = self.actions
            mask = np.zeros(acts.n, dtype=np.int8)
            mask[acts.stay] = 1
            free = self.node_occupant == -1
            if s == HOVERING:
                mask[_NODES:_NODES + self.layout.n_nodes] = free
            else:
                mask[acts.takeoff] = 1
                mask[_NODES:_NODES + self.layout.n_ports] = free[: self.layout.n_ports]
            atc = self.cfg.atc
            if atc.energy_check:  # clear only flights the battery can finish, with the reserve
                node = self.node.item(v)
                budget = self.battery.item(v) - atc.energy_reserve_pct
                hop = self.energy.hop_pct[node]
                mask[_NODES:_NODES + self.layout.n_nodes] &= hop < budget
                if s != HOVERING:
                    mask[acts.takeoff] = self.energy.trip_pct[node, self.dest.item(v)] < budget
                else:  # hold only while a landing can still be cleared at the next turn
                    ports = np.flatnonzero(mask[_NODES:_NODES + self.layout.n_ports])
                    if ports.size and budget - self._hold_pct <= hop[ports].min():
                        mask[acts.stay] = 0
                        mask[_NODES + self.layout.n_ports:_NODES + self.layout.n_nodes] = 0
            mask.setflags(write=False)
        self._mask_cache[v] = mask
        return mask

    def flight_energy_pct(self, v: int, action: int) -> float:
        """Battery (percent, no gusts) that ``action`` (a take-off or a move to a node) of vehicle
        ``v``, on the ground or hovering at a node, needs to be finished; 0 for other actions."""
        node = self.node.item(v)
        if node < 0:
            return 0.0
        if action == self.actions.takeoff and self._is_port[node]:
            return float(self.energy.trip_pct[node, self.dest.item(v)])
        if _NODES <= action < _NODES + self.layout.n_nodes:
            return float(self.energy.hop_pct[node, action - _NODES])
        return 0.0

    def _status_masks(self) -> tuple[np.ndarray | None, ...]:
        """By status code, the read-only mask of a status whose legal actions do not depend on
        the occupancy of the nodes, or ``None``."""
        acts = self.actions
        legal = {TAXIING: (acts.continue_, acts.avoid), DEPARTING: (acts.continue_, acts.avoid),
                 ARRIVING: (acts.continue_, acts.avoid), AWAY: (acts.continue_,),
                 OUT_OF_SERVICE: (acts.stay,)}
        masks: list[np.ndarray | None] = []
        for status in range(len(STATUS_NAMES)):
            if status not in legal:
                masks.append(None)
                continue
            mask = np.zeros(acts.n, dtype=np.int8)
            mask[list(legal[status])] = 1
            mask.setflags(write=False)
            masks.append(mask)
        return tuple(masks)

    def single_legal_action(self, v: int) -> int | None:
        """The one legal action of vehicle ``v`` now, or ``None`` when it has several."""
        only = self._fixed_single[self.status.item(v)]
        if only is not None:
            return only if only >= 0 else None
        legal = np.flatnonzero(self.action_mask(v))
        return int(legal[0]) if legal.size == 1 else None

    def has_decision(self, v: int) -> bool:
        return self.status[v] != AWAY and self.status[v] != OUT_OF_SERVICE

    def _choose_actor(self, first: bool = False) -> None:
        if first:
            candidate = 0
        else:
            candidate = (self.acting + 1) % self.n
        if self.cfg.atc.skip_agents_without_decision:
            for k in range(self.n):
                v = (candidate + k) % self.n
                if self.has_decision(v):
                    candidate = v
                    break
        self.acting = candidate

    # ================================================================== the step
    def check_action(self, v: int, action: Any) -> int:
        """Return ``action`` as an int if it is legal for vehicle ``v``, else raise."""
        mask = self.action_mask(v)
        if (type(action) is int or isinstance(action, np.integer)) and 0 <= action < len(mask) \
                and mask[action]:
            return int(action)
        names = self.actions.names(self.layout)
        legal = format_actions(np.flatnonzero(mask), names)
        if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
            if isinstance(action, np.ndarray) and action.shape == () and np.issubdtype(action.dtype, np.integer):
                action = int(action)
            else:
                raise IllegalActionError(
                    f"evtol_{v}: action {action!r} has type {type(action).__name__}, expected an "
                    f"integer in [0, {self.actions.n - 1}]; legal actions now: {legal}")
        a = int(action)
        if a < 0 or a >= self.actions.n:
            raise IllegalActionError(
                f"evtol_{v}: action {a} is out of range [0, {self.actions.n - 1}]; legal actions "
                f"now: {legal}")
        if not mask[a]:
            raise IllegalActionError(
                f"evtol_{v}: action {a} ({names[a]}) is masked out in status "
                f"{STATUS_NAMES[self.status[v]]}; legal actions now: {legal}")
        return a

    def step(self, action: Any) -> tuple[float, dict[str, Any]]:
        """Apply ``action`` for the acting vehicle, advance the world one step.

        Raises:
            IllegalActionError: before any change, if the action is not legal.

        Returns:
            ``(reward of the acting vehicle, info of the step)``.
        """
        v = self.acting
        a = self.check_action(v, action)
        cfg, rng, acts = self.cfg, self.rng, self.actions
        un = cfg.uncertainty
        commanded = a
        if un.action_misread_prob > 0:
            a = self.uncertainty.misread(rng, a, self.action_mask(v))
        metrics = self.metrics
        info: dict[str, Any] = {
            "minute": self.minute, "acting_agent": self._agent_names[v], "action": a,
            "commanded_action": commanded, "takeoff": False, "good_takeoff": False,
            "takeoff_failed": False, "landing": False, "good_landing": False,
        }
        rm = self.reward_model

        # ---- safety term, from the state before anything moves (paper eqs. 3-5)
        safety = rm.safety(self.conflict.item(v), a == acts.avoid)
        info["conflict"] = safety != 0.0

        # ---- apply the action
        tau = gamma = 0.0
        now = self.minute
        if a == acts.takeoff:
            if self.uncertainty.takeoff_fails(rng):
                info["takeoff_failed"] = True
                metrics.failed_takeoffs += 1
            else:
                tau, good = rm.takeoff(now, self.pending_time.item(v), self.battery.item(v))
                info["takeoff"], info["good_takeoff"] = True, good
                metrics.takeoffs += 1
                metrics.good_takeoffs += int(good)
                self._complete_operation(v, now)
                self._start_departure(v)
        elif _NODES <= a < _NODES + self.layout.n_nodes:
            node = a - _NODES
            landing = self.status[v] == HOVERING and self._is_port[node]
            if landing:
                gamma, good = rm.landing(now, self.pending_time.item(v), self.battery.item(v))
                info["landing"], info["good_landing"] = True, good
                metrics.landings += 1
                metrics.good_landings += int(good)
                self._complete_operation(v, now)
                self.landing_cleared[v] = True
            route = self._local_route(v, node)
            self._release(v)
            self._occupy(v, node)
            self.status[v] = TAXIING
            self._set_route(v, route, self.cfg.flight.hover_altitude_m)
            self.physics.make_dynamic(v)
        elif a == acts.avoid:
            self._avoid(v)
        # stay / continue: nothing changes.

        # ---- advance the world one step
        status_during = self.status.tolist()
        start_xyz = self.pos.tolist()
        self.prev_pos[:] = self.pos
        gusts, end_xyz = self._move(status_during, start_xyz)
        info["gusts"] = gusts
        info["separation_losses"], info["contacts"] = self._measure_separation(
            status_during, start_xyz, end_xyz)
        info["touchdowns"] = self._process_arrivals(end_xyz)
        if self._holding:
            for h in sorted(self._holding):
                self._assign_hover_spot(h)
        failed_nodes = self.uncertainty.failed_chargers(rng, self._charging_node_list)
        info["charger_failures"] = len(failed_nodes)
        lost_before = self.metrics.stranded_air + self.metrics.stranded_ground
        info["battery_depletions"] = self._update_battery(status_during, failed_nodes)
        info["stranded_ground"] = self._mark_stranded_on_ground()
        info["vehicles_lost"] = self.metrics.stranded_air + self.metrics.stranded_ground - lost_before
        self.minute += self.minutes_per_step
        self.step_count += 1
        self._update_delays()

        # ---- reward of the acting vehicle (paper's eq. 2)
        lam, beta = self.battery_delay_terms(v)
        reward = rm.total(tau, gamma, lam, beta, safety)
        info["reward_terms"] = {"takeoff": tau, "landing": gamma, "battery": lam, "delay": beta,
                                "safety": safety}
        metrics.steps += 1
        metrics.total_reward += reward
        metrics.collisions += int(safety < 0)
        metrics.avoided_conflicts += int(safety > 0)
        metrics.action_counts[a] += 1

        self._refresh_conflicts()
        self._mask_cache = {}
        self._evtol_cache = None
        self._port_cache = None
        self._choose_actor()
        self._draw_observation_noise()
        self.last_info = info
        return float(reward), info

    def battery_delay_terms(self, v: int) -> tuple[float, float]:
        """The paper's battery term lambda and delay term beta of vehicle ``v`` now, before
        their weights (:class:`~marl_vertiport.sim.reward.RewardModel`)."""
        rm = self.reward_model
        return rm.battery(self.battery.item(v)), rm.delay(self.delay.item(v))

    @property
    def truncated(self) -> bool:
        return self.step_count >= self.cfg.schedule.episode_steps

    def episode_metrics(self) -> dict[str, Any]:
        lost_min = float(np.sum(self.minute - self.lost_min[self.lost]))
        return self.metrics.summary(self.completed_delay + self.delay, lost_min)

    # ================================================================== action effects
    def _complete_operation(self, v: int, now: float) -> None:
        self.completed_delay[v] += self.schedule.lateness_min(now, self.pending_time.item(v))
        self.pending_kind[v] = NO_OPERATION
        self.delay[v] = 0.0

    def _start_departure(self, v: int) -> None:
        alt = self.cfg.flight.transit_altitude_m
        x, y, _ = self.pos[v]
        dest_xy = self.layout.destination_xy_m[self.dest[v]]
        exit_xy = self.layout.boundary_point(self.pos[v, :2], dest_xy)
        self._release(v)
        self.status[v] = DEPARTING
        self._set_route(v, [np.array([x, y, alt]), np.array([exit_xy[0], exit_xy[1], alt])], alt)
        self.physics.make_dynamic(v)

    def _avoid(self, v: int) -> None:
        """Climb to the lowest avoidance layer no other vehicle uses and fly the rest of the
        leg there. Hold position for this step instead when no horizontal travel is left (the
        final descent onto a spot) or when every layer is taken."""
        if self.avoid_layer[v] >= 0 or not self.has_target[v]:
            return
        waypoints = [self.target[v]] + self.routes[v]
        horizontal = [w for w in waypoints if np.hypot(*(w[:2] - self.pos[v, :2])) > 1e-9]
        used = set(self.avoid_layer[self.avoid_layer >= 0].tolist())
        layers = self.cfg.flight.avoid_altitudes_m
        free = [k for k in range(len(layers)) if k not in used]
        if not free or not horizontal:
            # The route resumes next step from where the vehicle holds now.
            self.routes[v].insert(0, self.target[v].copy())
            self.target[v] = self.pos[v].copy()
            return
        k = free[0]
        alt = layers[k]
        self.avoid_layer[v] = k
        final = waypoints[-1]
        new_route = [np.array([self.pos[v, 0], self.pos[v, 1], alt])]
        for w in horizontal:
            new_route.append(np.array([w[0], w[1], alt]))
        if abs(final[2] - alt) > 1e-9 and self.status[v] != DEPARTING:
            new_route.append(final.copy())
        # Drop duplicates created by the rewrite (consecutive equal waypoints).
        route = [new_route[0]]
        for w in new_route[1:]:
            if np.any(np.abs(w - route[-1]) > 1e-9):
                route.append(w)
        self._set_route(v, route, alt)

    # ================================================================== safety
    def _refresh_conflicts(self) -> None:
        """The ATC's conflict probe, for every vehicle in transit inside the airspace: its
        planned horizontal velocity (toward its current waypoint at cruise speed, 0 while it
        climbs or descends) and whether it is in a predicted conflict (the paper's check).

        A pair conflicts when both fly legs less than the separation apart in altitude, their
        planned 2-D paths come within the separation distance of each other (our reading of
        "intersecting paths" for vehicles with a footprint), and their closest approach lies
        ahead (``t_min >= 0``) and within the separation distance (eqs. 3-4). The relation is
        symmetric; the safety term of a step uses the acting vehicle's flag.
        """
        if self._any_conflict_probe:
            self.plan_vel_xy.fill(0.0)
            self.conflict.fill(False)
        cand = [v for v, (s, t) in enumerate(zip(self.status.tolist(), self.has_target.tolist()))
                if t and _IN_TRANSIT_INSIDE[s]]
        self._any_conflict_probe = bool(cand)
        if not cand:
            return
        speed = self.cfg.flight.cruise_speed_mps
        pos, target, routes = self.pos.tolist(), self.target.tolist(), self.routes
        vel, start, end = {}, {}, {}
        for v in cand:
            start[v] = (pos[v][0], pos[v][1])
            vel[v] = planned_velocity(start[v], (target[v][0], target[v][1]), speed)
            last = routes[v][-1] if routes[v] else None
            end[v] = (target[v][0], target[v][1]) if last is None else (last.item(0), last.item(1))
            self.plan_vel_xy[v] = vel[v]
        if len(cand) < 2:
            return
        for a, b in conflicting_pairs(cand, start, end, vel, self.leg_alt.tolist(),
                                      self.cfg.safety.min_separation_m):
            self.conflict[a] = self.conflict[b] = True

    # ================================================================== motion
    def _move(self, status: list[int], start: list[list[float]]) -> tuple[int, list[list[float]]]:
        """Move every vehicle with a target for one step.

        Args:
            status: per vehicle, its status code during the step, ``N`` ints.
            start: per vehicle, its position at the start of the step, ``N`` lists ``[x, y, z]``.

        Returns:
            The number of gusts, and per vehicle its position at the end of the step (``N``
            lists; the vehicles that did not move share their row of ``start``).

        Fills ``self._moved`` (vehicles that had a target), ``self._moved_m`` (distance each
        flew this step) and ``self._deflected`` (bodies the engine pushed off their commanded
        motion: only a contact can do that, gusts are accounted for exactly).

        The per-vehicle work is scalar arithmetic on Python lists in the loop that makes the
        per-body engine calls anyway: for fleets of a few dozen it is several times cheaper than
        numpy on arrays of that size (measured; see docs/performance.md).
        """
        moving = self.has_target.nonzero()[0].tolist()
        moved_m: list[float] = []
        deflected: list[int] = []
        self._moved, self._moved_m, self._deflected = moving, moved_m, deflected
        if self._any_cmd_vel:
            self.cmd_vel[:] = 0.0
        self._any_cmd_vel = bool(moving)
        if not moving:
            return 0, start
        dt, step_len, park_z = self.dt_s, self.step_len_m, self.park_z_m
        keep, n_gusts = self.uncertainty.gust_factors(self.rng, len(moving))
        targets = self.target.tolist()
        pos, cmd_vel = self.pos, self.cmd_vel
        radius = self.layout.airspace_radius_m
        end = list(start)
        bodies, body_vel, body_keep = [], [], []
        for k, v in enumerate(moving):
            px, py, pz = start[v]
            tx, ty, tz = targets[v]
            dx, dy, dz = tx - px, ty - py, tz - pz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            scale = (step_len / dist if dist > step_len else 1.0) / dt
            vel = (dx * scale, dy * scale, dz * scale)
            cmd_vel[v] = vel
            f = 1.0 if keep is None else keep[k]
            if f < 0.0 and vel[2] > 0.0 and pz + vel[2] * dt * f < park_z:
                # The ground stops a reversing gust: a vehicle climbing from its pad is pushed
                # back down to the pad at most, never below it.
                f = (park_z - pz) / (vel[2] * dt)
            if status[v] == AWAY:
                nx, ny, nz = px + vel[0] * dt * f, py + vel[1] * dt * f, pz + vel[2] * dt * f
                r = math.hypot(nx, ny)
                if f < 0.0 and r < radius and not self.returning[v]:
                    # A reversing gust pushed an outbound vehicle back toward the airspace:
                    # it holds at the boundary (it would otherwise be inside without a body).
                    nx, ny = nx * radius / r, ny * radius / r
                pos[v] = end[v] = [nx, ny, nz]
            else:
                bodies.append(v)
                body_vel.append(vel)
                body_keep.append(f)
        if bodies:
            new_pos = self.physics.step(bodies, body_vel, None if keep is None else body_keep)
            for v, p, vel, f in zip(bodies, new_pos, body_vel, body_keep):
                s = start[v]
                pos[v] = end[v] = [p[0], p[1], p[2]]
                off = max(abs(p[0] - s[0] - vel[0] * dt * f), abs(p[1] - s[1] - vel[1] * dt * f),
                          abs(p[2] - s[2] - vel[2] * dt * f))
                if off > _DEFLECTION_TOL_M:
                    deflected.append(v)
        for v in moving:
            moved_m.append(math.dist(end[v], start[v]))
        return n_gusts, end

    def _process_arrivals(self, end: list[list[float]]) -> int:
        """Advance routes of vehicles that reached their waypoint; returns touchdowns.

        ``end``: per vehicle, its position after this step's motion (``N`` lists)."""
        if not self._moved:
            return 0
        touchdowns = 0
        targets = self.target.tolist()
        for v in self._moved:
            p, t = end[v], targets[v]
            if max(abs(p[0] - t[0]), abs(p[1] - t[1]), abs(p[2] - t[2])) >= 1e-6:
                continue
            if self.routes[v]:
                self.target[v] = self.routes[v].pop(0)
                continue
            self.has_target[v] = False
            touchdowns += self._finish_leg(v)
        return touchdowns

    def _finish_leg(self, v: int) -> int:
        s = self.status[v]
        lay, cfg = self.layout, self.cfg
        self.avoid_layer[v] = -1
        if s == TAXIING or s == ARRIVING:
            node = self.node[v]
            self.pos[v] = self._node_pos[node]
            self.physics.make_static(v, self.pos[v])
            if lay.node_type[node] == HOVER_SPOT:
                self.status[v] = HOVERING
                return 0
            self.status[v] = ON_CHARGER if lay.node_type[node] == CHARGING_PORT else ON_PORT
            if self.landing_cleared[v]:
                self.landing_cleared[v] = False
                self.pending_kind[v] = PENDING_TAKEOFF
                self.pending_time[v] = self.schedule.takeoff_after_landing_min(
                    self.rng, self.minute + self.minutes_per_step)
                self.dest[v] = int(self.rng.integers(len(lay.destination_xy_m)))
                self.metrics.completed_trips += 1
                return 1
            return 0
        if s == DEPARTING:
            self.status[v] = AWAY
            self.returning[v] = False
            self.physics.make_absent(v)
            d = lay.destination_xy_m[self.dest[v]]
            self._set_route(v, [np.array([d[0], d[1], self.pos[v, 2]])], self.pos[v, 2])
            return 0
        if s == AWAY and not self.returning[v]:
            self.returning[v] = True
            entry = lay.boundary_point(np.zeros(2), self.pos[v, :2])
            # Aim slightly inside the boundary so the re-entry is unambiguous.
            entry = entry * (1.0 - 1e-3)
            alt = cfg.flight.transit_altitude_m
            self._set_route(v, [np.array([entry[0], entry[1], alt])], alt)
            return 0
        if s == AWAY:
            self.status[v] = ARRIVING
            self.returning[v] = False
            self.pending_kind[v] = PENDING_LANDING
            self.pending_time[v] = self.schedule.landing_min(self.minute + self.minutes_per_step)
            self.physics.make_static(v, self.pos[v])
            self._assign_hover_spot(v)
            return 0
        return 0

    def _assign_hover_spot(self, v: int) -> None:
        """Send an arriving vehicle to the free hover spot nearest to it, or hold it."""
        lay = self.layout
        free = np.flatnonzero((lay.node_type == HOVER_SPOT) & (self.node_occupant == -1))
        if free.size == 0:
            self._holding.add(v)  # holds at the boundary until a spot frees up
            return
        self._holding.discard(v)
        d = np.linalg.norm(lay.node_xy_m[free] - self.pos[v, :2], axis=1)
        node = int(free[np.argmin(d)])
        self._occupy(v, node)
        alt = self.cfg.flight.transit_altitude_m
        nx, ny = lay.node_xy_m[node]
        self._set_route(v, [np.array([nx, ny, alt]), self._node_pos[node].copy()], alt)
        self.physics.make_dynamic(v)

    # ================================================================== measurement
    def _measure_separation(self, status: list[int], start: list[list[float]],
                            end: list[list[float]]) -> tuple[int, int]:
        """New losses of separation (swept over the step) and new engine contacts.

        Args:
            status: per vehicle, its status code during the step, ``N`` ints.
            start, end: per vehicle, its position at the start and at the end of the step's
                motion, ``N`` lists ``[x, y, z]``.

        Only pairs with a vehicle that flew inside the airspace this step can change; pairs of
        vehicles that stood still keep their state.
        """
        movers = [v for v in self._moved if end[v] != start[v] and status[v] != AWAY]
        n = self.n
        if n < 2 or not movers:
            return 0, 0
        present = [s != AWAY for s in status]
        mover_set = set(movers)
        # Every pair of present vehicles with a mover in it, in sorted order.
        if len(movers) == 1:
            m = movers[0]
            pairs = [(o, m) if o < m else (m, o) for o in range(n) if o != m and present[o]]
        else:
            pairs = [(a, b) for a in range(n) if present[a]
                     for b in range(a + 1, n) if present[b] and (a in mover_set or b in mover_set)]
        if not pairs:
            return 0, 0
        dmin = swept_distances_m(self.prev_pos, self.pos, pairs, start, end)
        sep = self.cfg.safety.min_separation_m
        losses = {pair for pair, d in zip(pairs, dmin) if d < sep}
        kept = {pair for pair in self.sep_state if pair[0] not in mover_set and pair[1] not in mover_set}
        new_losses = len(losses - self.sep_state)
        self.sep_state = kept | losses
        self.metrics.separation_losses += new_losses
        # Engine contacts: those left at the end of the step, and those resolved within its
        # substeps (a deflected body and a vehicle that came within touching distance of it).
        contacts = set(self.physics.contact_pairs())
        if contacts or min(dmin) < self._near_m:
            # Each step's near passes and contacts are resolved afresh: the engine caches, for a
            # pair of bodies close enough to be checked, its contact points and the last
            # separating axis, and would warm-start the next step from them, a state no snapshot
            # holds, so a restored world would step differently.
            self.physics.forget_contacts()
        if self._deflected:
            deflected = set(self._deflected)
            contacts.update(pair for pair, d in zip(pairs, dmin)
                            if d <= self._touch_m and (pair[0] in deflected or pair[1] in deflected))
        kept = {pair for pair in self.contact_state
                if pair[0] not in mover_set and pair[1] not in mover_set}
        new_contacts = len(contacts - self.contact_state)
        self.contact_state = kept | contacts
        self.metrics.contacts += new_contacts
        return new_losses, new_contacts

    def _update_battery(self, status_during: list[int], failed_nodes: list[int]) -> int:
        """Drain or charge every battery for the step; take depleted airborne vehicles out of
        service. Returns the number of depletions.

        Args:
            status_during: per vehicle, its status while it moved this step (``N`` ints).
            failed_nodes: charging nodes whose charger failed this step.

        Scalar per vehicle, as :meth:`_move`: a handful of numpy calls on ``N``-vectors cost
        more than the loop for fleets of a few dozen."""
        failed_charging = ()
        if failed_nodes:
            # A charger that fails this step leaves its vehicle idling on the ground.
            node = self.node.tolist()
            failed_charging = [v for v, s in enumerate(status_during)
                               if s == ON_CHARGER and node[v] in failed_nodes]
        change = self.battery_model.changes(status_during, zip(self._moved, self._moved_m),
                                            failed_charging)
        level = self.battery_model.apply(self.battery.tolist(), change)
        empty = [v for v, b in enumerate(level) if b <= 0.0 and _AIRBORNE[status_during[v]]]
        self.battery[:] = level
        # The fleet's mean battery for the episode metric. Below 8 values numpy's sum adds them
        # in order, as sum() does; from 8 on it adds pairwise, so it is asked itself.
        total = sum(level) if self.n < 8 else float(np.add.reduce(self.battery))
        self.metrics.battery_sum += total / self.n
        if not empty:
            return 0
        status = self.status.tolist()
        depleted = [v for v in empty if status[v] != OUT_OF_SERVICE]
        end = self.minute + self.minutes_per_step
        for v in depleted:
            self._take_out_of_service(v)
            if not self.lost[v]:
                self.lost[v] = True
                self.lost_min[v] = end
                self.metrics.stranded_air += 1
        self.metrics.battery_depletions += len(depleted)
        return len(depleted)

    def _mark_stranded_on_ground(self) -> int:
        """Mark the vehicles stranded on the ground in this step; returns how many.

        A vehicle on a normal port is stranded when no flight it may still be cleared for can
        bring it back into service: its battery does not cover the hop to a usable charging
        port (one not blocked for the day by a vehicle out of service), or, where no charging
        port is usable, a take-off (:meth:`stranded_threshold_pct`). Idling only drains it
        further, so it stays stranded for the rest of the day."""
        status = self.status.tolist()
        lost = self.lost.tolist()
        candidates = [v for v, s in enumerate(status) if s == ON_PORT and not lost[v]]
        if not candidates:
            return 0
        battery = self.battery.tolist()
        end = self.minute + self.minutes_per_step
        marked = 0
        for v in candidates:
            if battery[v] <= self.stranded_threshold_pct(v):
                self.lost[v] = True
                self.lost_min[v] = end
                marked += 1
        self.metrics.stranded_ground += marked
        return marked

    def stranded_threshold_pct(self, v: int) -> float:
        """Battery (percent) at or below which vehicle ``v``, on the ground at a port, can never
        charge again: the least energy of a hop to a usable charging port (one not occupied by
        a vehicle out of service), or of a take-off where no charging port is usable, plus
        ``atc.energy_reserve_pct`` when the ATC checks energy (the flight is not cleared below
        that). A vehicle on a working charging port is never stranded (0 is returned)."""
        node = self.node.item(v)
        if node < 0 or self.layout.node_type[node] == CHARGING_PORT:
            return 0.0
        occupant, status = self.node_occupant.tolist(), self.status.tolist()
        usable = [c for c in self._charging_nodes.tolist()
                  if occupant[c] < 0 or status[occupant[c]] != OUT_OF_SERVICE]
        hop = self.energy.hop_pct[node]
        need = min(hop[c] for c in usable) if usable else float(self.energy.trip_pct[node, self.dest.item(v)])
        atc = self.cfg.atc
        return float(need + (atc.energy_reserve_pct if atc.energy_check else 0.0))

    def _take_out_of_service(self, v: int) -> None:
        """Battery depleted in the air: emergency landing where it is, out of service for the
        rest of the day. If it comes down within two vehicle sizes of a free port it takes the
        nearest such port, so nothing lands on top of it; it never comes down on or inside a
        vehicle on the ground (:meth:`_clear_landing_xy`). A late
        operation it leaves undone keeps its lateness (at the end of this step) in the metrics."""
        if self.pending_kind[v] != NO_OPERATION:
            self.completed_delay[v] += self.schedule.lateness_min(
                self.minute + self.minutes_per_step, self.pending_time.item(v))
        self.has_target[v] = False
        self.routes[v] = []
        self.avoid_layer[v] = -1
        self.landing_cleared[v] = False
        self.pending_kind[v] = NO_OPERATION
        self._release(v)
        inside = self.status[v] != AWAY
        self.status[v] = OUT_OF_SERVICE
        if inside:
            self.pos[v, 2] = self.park_z_m
            d = np.linalg.norm(self.layout.node_xy_m - self.pos[v, :2], axis=1)
            near = np.flatnonzero((d < self.cfg.flight.vehicle_size_m * 2) & self._is_port
                                  & (self.node_occupant == -1))
            if near.size:
                self._occupy(v, int(near[np.argmin(d[near])]))
            self.pos[v, :2] = self._clear_landing_xy(v)
            self.physics.make_static(v, self.pos[v])

    def _clear_landing_xy(self, v: int) -> np.ndarray:
        """Where vehicle ``v`` comes down in an emergency landing: straight below it, or, when
        that would put it within touching distance of a vehicle on the ground, the nearest point
        clear of all of them (on rings of one touching distance around it, 12 bearings each,
        inside the airspace), so that it never lands on or inside another vehicle."""
        here = self.pos[v, :2].copy()
        grounded = [u for u in range(self.n) if u != v and self.pos[u, 2] <= self.park_z_m + 1e-6
                    and self.status[u] != AWAY]
        if not grounded:
            return here
        others = self.pos[grounded, :2]
        clear = self._touch_m
        if np.linalg.norm(others - here, axis=1).min() >= clear:
            return here
        radius = self.layout.airspace_radius_m
        bearings = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
        for ring in range(1, 4 * self.n + 2):
            points = here + ring * clear * np.column_stack([np.cos(bearings), np.sin(bearings)])
            ok = (np.linalg.norm(points[:, None] - others[None], axis=2).min(axis=1) >= clear) \
                & (np.linalg.norm(points, axis=1) < radius)
            if ok.any():
                return points[np.flatnonzero(ok)[0]]
        return here  # pragma: no cover - a full airspace; cannot happen with a valid layout

    def _update_delays(self) -> None:
        """Minutes since each pending operation's time, and the delay (that lateness beyond the
        tolerance, else 0), shape ``(N,)``."""
        self.delay[:] = self.schedule.delays_min(self.minute, self.pending_time,
                                                 self.pending_kind.tolist(), self._rel_min)

    def _draw_observation_noise(self) -> None:
        self.obs_xy = self.uncertainty.observed_xy(self.rng, self.pos[:, :2])

    # ================================================================== graph features
    def schedule_status(self) -> np.ndarray:
        """-1 early, 0 on time, 1 delayed, per vehicle, shape ``(N,)``."""
        return self.schedule.status_codes(self.minute, self.pending_time, self.pending_kind)

    def _evtol_base(self) -> np.ndarray:
        """eVTOL node features ``(N, 13)`` float32 with ``is_self`` 0, cached until the next step.

        Built as one flat list of Python numbers, converted to float32 in one call (a flat list
        converts about twice as fast as nested rows): for the paper's 4 vehicles about a third
        of the cost of a dozen column assignments and the array masks of
        :meth:`schedule_status` (which gives the same column), for 16 about the same cost."""
        if self._evtol_cache is None:
            status_code = self.schedule.status_code
            values: list[float] = []
            # _rel_min holds minute - pending_time, as of the last step.
            for st, bat, pk, rel, (ox, oy), (_, _, z), (vx, vy), d, c, nd in zip(
                    self.status.tolist(), self.battery.tolist(), self.pending_kind.tolist(),
                    self._rel_min.tolist(), self.obs_xy.tolist(),
                    self.pos.tolist(), self.plan_vel_xy.tolist(), self.delay.tolist(),
                    self.conflict.tolist(), self.node.tolist()):
                values += (st, bat, status_code(rel, pk), ox, oy, z, vx, vy,
                           -rel if pk != NO_OPERATION else 0.0, d, c, nd, 0.0)
            self._evtol_cache = np.array(values, dtype=np.float32).reshape(self.n, len(EVTOL_FEATURES))
        return self._evtol_cache

    def port_nodes(self) -> np.ndarray:
        """Vertiport graph node features ``(P, 4)``: available, type, x_m, y_m (a new array;
        built once a step)."""
        if self._port_cache is None:
            f = self._port_static.copy()
            f[:, 0] = self.node_occupant == -1
            self._port_cache = f
        return self._port_cache.copy()

    def evtol_nodes(self, observer: int) -> np.ndarray:
        """eVTOL graph node features ``(N, 13)`` as seen by vehicle ``observer``."""
        f = self._evtol_base().copy()
        f[observer, _IS_SELF] = 1.0
        return f

    def self_features(self, v: int) -> np.ndarray:
        return self._evtol_base()[v, : len(SELF_FEATURES)].copy()

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Global, noise-free graph for a centralised critic."""
        base = self._evtol_base()
        evtol = np.empty((self.n, len(EVTOL_FEATURES) + len(STATE_EXTRA_FEATURES)), dtype=np.float32)
        evtol[:, : len(EVTOL_FEATURES)] = base
        evtol[:, 3:5] = self.pos[:, :2]
        evtol[:, _IS_SELF] = 0.0
        evtol[self.acting, _IS_SELF] = 1.0
        k = len(EVTOL_FEATURES)
        evtol[:, k] = self.cmd_vel[:, 2]
        evtol[:, k + 1:k + 3] = self.layout.destination_xy_m[self.dest]
        evtol[:, k + 3] = self.avoid_layer
        ports = np.empty((self.layout.n_nodes, len(STATE_PORT_FEATURES)), dtype=np.float32)
        ports[:, :4] = self.port_nodes()
        ports[:, 4] = self.node_occupant
        clock = np.array([self.minute, self.acting,
                          self.cfg.schedule.episode_steps - self.step_count], dtype=np.float32)
        return {"port_nodes": ports, "evtol_nodes": evtol, "clock": clock}

    def close(self) -> None:
        self.physics.close()
