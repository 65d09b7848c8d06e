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
from typing import Any

import numpy as np

from marl_vertiport.config import EnvConfig
from marl_vertiport.sim.avoidance import Avoidance
from marl_vertiport.sim.battery import BatteryModel
from marl_vertiport.sim.clearance import Clearance
from marl_vertiport.sim.energy import FlightEnergy
from marl_vertiport.sim.features import Features
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT, Layout
from marl_vertiport.sim.legality import IllegalActionError, Legality
from marl_vertiport.sim.lifecycle import Lifecycle
from marl_vertiport.sim.metrics import EpisodeMetrics
from marl_vertiport.sim.motion import Motion
from marl_vertiport.sim.physics import FlightPhysics
from marl_vertiport.sim.reward import RewardModel
from marl_vertiport.sim.schedule import FlightSchedule
from marl_vertiport.sim.schema import (
    AIRBORNE, AWAY, HOVERING, LEADING_ACTIONS, ON_CHARGER, ON_PORT, OUT_OF_SERVICE,
    PENDING_LANDING, PENDING_TAKEOFF, TAXIING, ActionLayout,
)
from marl_vertiport.sim.separation import Separation
from marl_vertiport.sim.stranding import Stranding
from marl_vertiport.sim.trailing import Trailing
from marl_vertiport.sim.uncertainty import KeyedDraws, Uncertainty, twin_generator

__all__ = ["IllegalActionError", "VertiportSim"]

#: Index of the first node action ("go to node 0"): the action layout of sim/schema.py.
_NODES = LEADING_ACTIONS

_SHARED = frozenset({int, float, bool, str, tuple, type(None)})  # tuples: of numbers


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
        return twin_generator(value)
    return copy.deepcopy(value)


class VertiportSim(Legality, Clearance, Avoidance, Trailing, Lifecycle, Motion, Separation,
                   Stranding, Features):
    """One vertiport, its fleet, and the round-robin ATC turn.

    This class holds the state of the day and the order of a step; each concern of the step is
    a part of it in a module of its own: :mod:`~marl_vertiport.sim.legality` (masks, the action
    check, the energy check), :mod:`~marl_vertiport.sim.lifecycle` (departures, avoidance,
    legs, hover spots, emergency landings), :mod:`~marl_vertiport.sim.motion` (flight and
    arrivals), :mod:`~marl_vertiport.sim.separation` (the conflict probe and the separation
    flown), :mod:`~marl_vertiport.sim.stranding` (batteries and lost vehicles) and
    :mod:`~marl_vertiport.sim.features` (the graph features).

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
        # Every pair of vehicles (i < j), in sorted order: the candidates of the separation
        # measured with arrays (sim/separation.py).
        self._pair_i, self._pair_j = np.triu_indices(self.n, 1)
        self.battery_model = BatteryModel(config.battery, AIRBORNE, ON_PORT, ON_CHARGER)
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
        self._flight_masks = self._in_flight_masks()
        # By status code: the action of a fixed mask with one legal action, -1 for a fixed mask
        # with several, None where the mask depends on the state.
        self._fixed_single = tuple(
            None if m is None else int(np.flatnonzero(m)[0]) if m.sum() == 1 else -1
            for m in self._fixed_masks)
        self.energy = FlightEnergy(config, self.layout)
        # Battery a hovering vehicle spends until its next turn (at most a full round).
        self._hold_pct = config.battery.hover_drain_pct * self.n
        self._init_clearance()
        # Everything set so far is fixed for the env's life; what follows is episode state,
        # which snapshot() copies.
        self._static_keys = frozenset(self.__dict__) | {"_static_keys"}
        self.rng = np.random.default_rng(0)
        #: The keyed streams of ``uncertainty.common_random_numbers`` (None without).
        self.draws: KeyedDraws | None = None
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
        self._trip_ends: list[int] = []  # vehicles whose trip touched down in this step
        # Rules v1 (sim/clearance.py): each vehicle's reserved volume (an id, -1: none), where
        # its current segment began, its holding slot (-1: none), and the vehicles back from
        # their destination that wait outside for a slot.
        self.reservation = np.full(n, -1, dtype=np.int64)
        self.reserved: list[tuple | None] = [None] * n  # the volumes the ids name
        self.release_at: list[tuple | None] = [None] * n  # the quick test of a release
        self.seg_from = np.zeros((n, 3))
        self.slot_of = np.full(n, -1, dtype=np.int64)
        self._waiting_outside: set[int] = set()
        self._gone: set[int] = set()  # out of service outside the airspace
        # Rules v1, trailing a departure: each vehicle's clearance number (newer: larger) and the
        # departing vehicles it yields to (its leaders).
        self.clear_seq = np.zeros(n, dtype=np.int64)
        self._clear_count = 0
        self.leaders: list[tuple[int, ...]] = [()] * n

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
        self.seg_from[:] = self.pos
        if self.sep_check:
            self._trim_memos()
            for v in range(n):
                self._reserve(v)
        self.physics.forget_contacts()  # nothing of the previous day's contacts carries over
        self._update_delays()
        self._refresh_conflicts()
        self.metrics = EpisodeMetrics(action_counts=np.zeros(self.actions.n, dtype=np.int64),
                                      min_separation_m=self._initial_separation_m())
        self.acting = 0
        self._choose_actor(first=True)
        self.draws = (KeyedDraws.from_generator(rng, n, len(self._charging_node_list),
                                                self.uncertainty.noisy_observations)
                      if cfg.uncertainty.common_random_numbers else None)
        self._draw_observation_noise()
        self._mask_cache: dict[int, np.ndarray] = {}
        self._evtol_cache: np.ndarray | None = None
        self._port_cache: np.ndarray | None = None
        self.last_info: dict[str, Any] = {}
        #: The charging nodes whose charger failed in the last step (for the renderer; the
        #: step's info counts them as ``charger_failures``).
        self.last_failed_chargers: tuple[int, ...] = ()

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
        if self.sep_check:  # the reservation ids name entries of this sim's memo table
            self._reintern()
        if not self.uncertainty.noisy_observations:
            self.obs_xy = self.pos[:, :2]  # a view of the positions, as after a step

    # ================================================================== turns
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
    def step(self, action: Any) -> tuple[float, dict[str, Any]]:
        """Apply ``action`` for the acting vehicle, advance the world one step.

        Raises:
            IllegalActionError: before any change, if the action is not legal.

        Returns:
            ``(reward of the acting vehicle, info of the step)``.
        """
        if self.sep_check:
            self._check_memo()
        v = self.acting
        a = self.check_action(v, action)
        cfg, rng, acts, draws = self.cfg, self.rng, self.actions, self.draws
        un = cfg.uncertainty
        if draws is not None:
            draws.begin_step()
        commanded = a
        if un.action_misread_prob > 0:
            a = self.uncertainty.misread(rng, a, self.action_mask(v),
                                         None if draws is None else draws.misread_u)
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
            if self.uncertainty.takeoff_fails(rng if draws is None else draws.takeoffs[v]):
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
        if self.sep_state:
            metrics.separation_loss_min += self.minutes_per_step
        info["touchdowns"] = self._process_arrivals(end_xyz)
        if self._holding:
            for h in sorted(self._holding):
                self._assign_hover_spot(h)
        if self._waiting_outside:
            for w in sorted(self._waiting_outside):
                self._head_for_slot(w)
        failed_nodes = self.uncertainty.failed_chargers(
            rng, self._charging_node_list, None if draws is None else draws.charger_u)
        info["charger_failures"] = len(failed_nodes)
        self.last_failed_chargers = tuple(int(k) for k in failed_nodes)
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

    # ================================================================== clock and noise
    def _update_delays(self) -> None:
        """Minutes since each pending operation's time, and the delay (that lateness beyond the
        tolerance, else 0), shape ``(N,)``."""
        self.delay[:] = self.schedule.delays_min(self.minute, self.pending_time,
                                                 self.pending_kind.tolist(), self._rel_min)

    def _draw_observation_noise(self) -> None:
        draws = self.draws
        self.obs_xy = self.uncertainty.observed_xy(self.rng, self.pos[:, :2],
                                                   None if draws is None else draws.noise_z)

    def use_generator(self, rng: np.random.Generator) -> None:
        """Draw the rest of the day from ``rng`` (a look-ahead's own future after
        :meth:`restore`); with ``common_random_numbers``, from streams keyed by one draw of it."""
        self.rng = rng
        if self.draws is not None:
            self.draws = KeyedDraws.from_generator(rng, self.n, len(self._charging_node_list),
                                                   self.uncertainty.noisy_observations)

    def close(self) -> None:
        self.physics.close()
