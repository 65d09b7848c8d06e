"""A look-ahead planner: one step of policy improvement over the expert dispatcher.

For the vehicle whose turn it is, each candidate action is tried in a copy of the simulator
(:meth:`VertiportSim.snapshot` / :meth:`~VertiportSim.restore`), the dispatcher then runs the
whole fleet for ``horizon - 1`` more steps, and the action with the largest sum of rewards is
taken (the rollout algorithm of approximate dynamic programming: in expectation it does at least
as well as the policy it rolls out, up to the horizon's truncation).

It is a *model-based* controller: it reads the true simulator state, not only the observation,
and simulates ``horizon`` steps per candidate (tens of milliseconds a decision). Training uses
it as the teacher whose decisions the GCN actor learns to imitate from observations alone
(``pretrain.teacher: planner``); ``make evaluate AGENTS=planner`` scores it like any agent.

Rollouts draw the future (new flight plans, and gusts and failures where they are simulated)
from a generator of their own, the same for every candidate of a decision (common random
numbers), never from the env's. By default they run on the nominal model (``nominal=True``):
the env's config without wind gusts, charger failures, take-off failures or observation noise,
so that a candidate is not judged by a gust or a failure that one rollout happened to draw
(certainty-equivalent planning; on validation days of the paper's case 2 it scored about 950
a day against about 170 for rollouts with the uncertainties).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from agents.common.names import canonical_kwargs
from agents.controllers.base import Controller
from agents.controllers.dispatcher import DispatcherController
from marl_vertiport.config import EnvConfig
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE
from marl_vertiport.sim.layout import HOVER_SPOT
from marl_vertiport.spaces import ObservationBuilder


def _none(_v: int) -> None:
    return None


def nominal_config(cfg: EnvConfig) -> EnvConfig:
    """``cfg`` without its uncertainties: no wind gusts, charger or take-off failures,
    observation noise or action misreads (the model a certainty-equivalent planner rolls out)."""
    return dataclasses.replace(cfg, uncertainty=dataclasses.replace(
        cfg.uncertainty, wind_gust_prob=0.0, charger_failure_prob=0.0,
        takeoff_failure_prob=0.0, position_noise_mean_m=0.0, position_noise_std_m=0.0,
        action_misread_prob=0.0))


def roll_out(scratch: VertiportSim, builder: ObservationBuilder, base: Controller,
             snap: dict, action: int, steps: int, rng: np.random.Generator | None,
             watch: Callable[[VertiportSim], None] | None = None) -> float:
    """Simulate ``action`` from the episode state ``snap`` in ``scratch``, then ``base`` for the
    whole fleet for ``steps - 1`` more steps (fewer at the end of the day); return the sum of
    the acting vehicles' rewards. ``scratch`` holds the end state afterwards; the future is
    drawn from ``rng`` (``None``: from the generator in ``snap``, which draws the env's own
    future); ``watch(scratch)`` runs after every step.

    When ``base.act`` is a pure function of the observation (``pure_act``), a turn with a single
    legal action takes that action without asking it: it could return nothing else, and no state
    or generator of its own is skipped."""
    single = scratch.single_legal_action if getattr(base, "pure_act", False) else _none
    scratch.restore(snap)
    if rng is not None:
        scratch.use_generator(rng)
    total, _ = scratch.step(action)
    if watch is not None:
        watch(scratch)
    for _ in range(steps - 1):
        if scratch.truncated:
            break
        v = scratch.acting
        only = single(v)
        reward, _ = scratch.step(base.act(builder.observe(v)) if only is None else only)
        total += reward
        if watch is not None:
            watch(scratch)
    return total


def held_terms_value(sim: VertiportSim, turns_per_vehicle: float) -> float:
    """What the rest of the day is worth beyond a rollout's horizon, estimated as each vehicle's
    battery and delay terms held at their values in ``sim`` for its next ``turns_per_vehicle``
    turns (fewer near the end of the day). A vehicle out of service earns the worst of both for
    good, so a decision that strands a vehicle just before the horizon ends is charged for the
    rest of its day, not for a few steps; a vehicle under the battery threshold is charged the
    worst battery term as long as it stays there."""
    rw = sim.cfg.reward
    turns = min(turns_per_vehicle, (sim.cfg.schedule.episode_steps - sim.step_count) / sim.n)
    if turns <= 0:
        return 0.0
    lam_sum = beta_sum = 0.0
    for v in range(sim.n):
        lam, beta = sim.battery_delay_terms(v)
        lam_sum += lam
        beta_sum += -rw.term_magnitude if sim.status[v] == OUT_OF_SERVICE else beta
    return float(turns * (rw.battery_weight * lam_sum + rw.delay_weight * beta_sum))


class ScratchRollouts:
    """What a model-based controller needs to roll a controller out: a scratch copy of the bound
    env's simulator (without the config's uncertainties when ``nominal``) and its observation
    builder, both built once per config. Subclasses set ``rollout_policy`` (the controller that
    flies the rollouts) and ``nominal``; until :meth:`bind`, ``sim`` and the scratch copy are
    ``None``."""

    rollout_policy: Any
    nominal: bool
    sim: VertiportSim | None = None
    _scratch: VertiportSim | None = None
    _builder: ObservationBuilder | None = None

    def bind(self, sim: VertiportSim) -> None:
        """Act in the env whose simulator is ``sim``; the controller of the rollouts
        (:attr:`rollout_policy`) adopts the env's energy model, bound to the scratch copy."""
        cfg = nominal_config(sim.cfg) if self.nominal else sim.cfg
        if self._scratch is None or self._scratch.cfg != cfg:
            if self._scratch is not None:
                self._scratch.close()
            self._scratch = VertiportSim(cfg)
            self._builder = ObservationBuilder(self._scratch)
        if hasattr(self.rollout_policy, "bind"):
            self.rollout_policy.bind(self._scratch)
        self.sim = sim

    def close(self) -> None:
        if self._scratch is not None:
            self._scratch.close()
            self._scratch = None


class PlannerController(ScratchRollouts, Controller):
    """Chooses, among the legal actions of a vehicle on the ground or hovering, the one whose
    dispatcher rollout earns the most reward; in transit it acts as the dispatcher.

    Args:
        horizon: steps simulated per candidate action, the candidate's own step included.
        terminal_turns: turns per vehicle over which the state at the horizon is valued
            (:meth:`terminal_value`; 0: none).
        min_takeoff_battery_pct: least charge for a take-off to be a candidate (the dispatcher's
            charge for a trip); the dispatcher's own choice is always kept as a fallback.
        min_hover_battery_pct: at or below this charge a hovering vehicle lands if it can
            (staying is not a candidate; the dispatcher's reserve).
        stranding_penalty: cost, beyond the reward, of each vehicle that a rollout leaves out of
            service or empty: the planner does not buy reward for the rest of the fleet by
            sacrificing a vehicle (an emergency landing), which the reward alone can favour.
        margin: reward by which another action must beat the dispatcher's choice to replace it
            (a margin keeps near-ties with the dispatcher, which makes the planner's choices
            easier to learn from observations).
        seed: seed of the rollouts' generator (combined with the env's step count).
        rollout_policy: the controller that flies the rollouts and whose choice is the
            fallback (default: the expert dispatcher); ``base`` is its name before 0.2.0.
        nominal: simulate rollouts without the config's uncertainties (gusts, charger and
            take-off failures, observation noise); ``False``: with them.
        expect_failures: value a take-off as what it is worth in expectation under the env's
            ``takeoff_failure_prob`` ``p``: ``(1 - p)`` times its rollout plus ``p`` times the
            rollout of staying (a failed take-off leaves the vehicle on its port, and the step
            is the stay's, reward and state alike), so that a take-off whose failure would
            leave the vehicle in a trap is weighed with that trap. Nominal rollouts only;
            no extra rollout (staying is a candidate on the ground).
        rescue: where every candidate loses a vehicle, or only the base's choice is left
            and it loses one, simulate the legal actions the candidates left out too (a
            take-off below ``min_takeoff_battery_pct``, a move to another hover spot) and
            take the best: the filters are there to save rollouts, not to forbid a way out.

    Call :meth:`bind` with the simulator of the env it acts in before the first ``act``
    (the episode runners in :mod:`agents.controllers.base` do this for any controller with ``bind``).
    """

    name = "planner"

    def __init__(self, horizon: int = 40, terminal_turns: float = 30.0,
                 min_takeoff_battery_pct: float = 80.0, margin: float = 0.0,
                 min_hover_battery_pct: float = 24.0, stranding_penalty: float = 1000.0,
                 seed: int = 0,
                 rollout_policy: Controller | None = None, nominal: bool = True,
                 expect_failures: bool = False, rescue: bool = False, **renamed: Any) -> None:
        renamed = canonical_kwargs(self.name, renamed)
        unknown = sorted(set(renamed) - {"rollout_policy"})
        if unknown:
            raise TypeError(f"PlannerController got unexpected argument(s) {unknown}")
        if "rollout_policy" in renamed:
            if rollout_policy is not None:
                raise TypeError("PlannerController: rollout_policy given twice (once as base)")
            rollout_policy = renamed["rollout_policy"]
        if horizon < 1:
            raise ValueError(f"horizon must be >= 1 step, got {horizon}")
        if terminal_turns < 0:
            raise ValueError(f"terminal_turns must be >= 0, got {terminal_turns}")
        self.horizon = int(horizon)
        self.terminal_turns = float(terminal_turns)
        self.min_takeoff_battery_pct = float(min_takeoff_battery_pct)
        self.margin = float(margin)
        self.stranding_penalty = float(stranding_penalty)
        self.min_hover_battery_pct = float(min_hover_battery_pct)
        self.seed = int(seed)
        if isinstance(rollout_policy, str):
            from agents.controllers.registry import make_controller

            rollout_policy = make_controller(rollout_policy)
        self.rollout_policy = rollout_policy if rollout_policy is not None else DispatcherController()
        self.nominal = bool(nominal)
        if expect_failures and not self.nominal:
            raise ValueError("expect_failures weighs nominal rollouts; with nominal=False the "
                             "rollouts draw the failures themselves")
        self.expect_failures = bool(expect_failures)
        self.rescue = bool(rescue)
        #: The candidates' values of the last decision (empty where none was simulated).
        self.last_q: dict[int, float] = {}
        #: Whether the last decision had a legal action ruled out as unsafe (staying aloft
        #: with a low battery), so that the choice carried the cost of a stranded vehicle.
        self.last_forced = False

    def candidates(self, sim: VertiportSim) -> list[int]:
        """Actions worth simulating for the acting vehicle: every legal action on the ground,
        except a take-off with less than ``min_takeoff_battery_pct`` (whose cost, a vehicle
        stranded on its way back, mostly falls beyond the horizon); when hovering, staying and
        landing (moves to another hover spot are left out), and only landing once the charge
        is down to ``min_hover_battery_pct``."""
        v = sim.acting
        legal = np.flatnonzero(sim.action_mask(v))
        if sim.battery[v] < self.min_takeoff_battery_pct:
            legal = legal[legal != sim.actions.takeoff]
        if sim.status[v] == HOVERING:
            hover_moves = sim.actions.node_action(0) + np.flatnonzero(sim.layout.node_type == HOVER_SPOT)
            legal = legal[~np.isin(legal, hover_moves)]
            if sim.battery[v] <= self.min_hover_battery_pct and legal.size > 1:
                legal = legal[legal != sim.actions.stay]  # low: land now, wherever is free
                self.last_forced = True
        return legal.tolist()

    def q_values(self, sim: VertiportSim, also: int | None = None) -> dict[int, float]:
        """Sum of rewards over the horizon for each candidate action of the acting vehicle, and
        for ``also`` (the base policy's own choice, such as a holding move) if it is not one."""
        return self._simulate(sim, self._with(self.candidates(sim), also))[0]

    @staticmethod
    def _with(actions: list[int], also: int | None) -> list[int]:
        if also is not None and also not in actions:
            actions.append(int(also))
        return actions

    def _simulate(self, sim: VertiportSim,
                  actions: list[int]) -> tuple[dict[int, float], set[int]]:
        """The value of each of ``actions`` (see :meth:`q_values`; each rollout is
        :func:`roll_out`), and those of them whose rollout lost a vehicle."""
        scratch, builder, base = self._scratch, self._builder, self.rollout_policy
        assert scratch is not None and builder is not None
        snap = sim.snapshot()
        q: dict[int, float] = {}
        losing: set[int] = set()
        for a in actions:
            total = roll_out(scratch, builder, base, snap, a, self.horizon,
                             np.random.default_rng((self.seed, sim.step_count)))
            stranded = self.stranded(scratch) - self.stranded(sim)
            q[a] = total + self.terminal_value(scratch) - self.stranding_penalty * stranded
            if stranded > 0:
                losing.add(a)
        return q, losing

    def _left_out(self, sim: VertiportSim, actions: list[int]) -> list[int]:
        """The legal actions of the acting vehicle that ``actions`` leave out."""
        return [a for a in np.flatnonzero(sim.action_mask(sim.acting)).tolist()
                if a not in actions]

    def _expected(self, sim: VertiportSim, q: dict[int, float]) -> dict[int, float]:
        """``q`` with a take-off valued in expectation over its failure (``expect_failures``):
        a failed take-off's step is the stay's, so its branch is the stay's rollout."""
        p = sim.cfg.uncertainty.takeoff_failure_prob
        takeoff, stay = sim.actions.takeoff, sim.actions.stay
        if not self.expect_failures or p <= 0 or takeoff not in q:
            return q
        if stay not in q:
            q.update(self._simulate(sim, [stay])[0])
        return {**q, takeoff: (1.0 - p) * q[takeoff] + p * q[stay]}

    @staticmethod
    def stranded(sim: VertiportSim) -> int:
        """Vehicles lost so far: depleted in the air or stranded on the ground (``sim.lost``)."""
        return int(np.count_nonzero(sim.lost))

    def terminal_value(self, sim: VertiportSim) -> float:
        """What the rest of the day is worth beyond the horizon (:func:`held_terms_value` over
        ``terminal_turns`` turns)."""
        return held_terms_value(sim, self.terminal_turns)

    def act(self, observation: dict) -> int:
        sim = self.sim
        if sim is None:
            raise RuntimeError("PlannerController needs the simulator: call bind(env.unwrapped.sim) "
                               "first (the episode runners of agents.controllers.base do)")
        fallback = self.rollout_policy.act(observation)
        self.last_q, self.last_forced = {}, False
        v = sim.acting
        if sim.status[v] not in (ON_PORT, ON_CHARGER, HOVERING):
            return fallback
        if not np.array_equal(observation["action_mask"], sim.action_mask(v)):
            raise RuntimeError("PlannerController: the observation is not that of the bound env's "
                               "acting vehicle")
        actions = self._with(self.candidates(sim), fallback)
        left_out = self._left_out(sim, actions) if self.rescue else []
        if len(actions) < 2 and not left_out:  # nothing to compare: the base's choice
            return fallback
        q, losing = self._simulate(sim, actions)
        if left_out and losing.issuperset(q):  # no candidate keeps the fleet: widen
            q.update(self._simulate(sim, left_out)[0])
        if len(q) < 2:  # the base's choice alone, and it keeps the fleet
            return fallback
        q = self.last_q = self._expected(sim, q)
        best = max(q, key=q.get)
        # Keep the dispatcher's choice unless another action is better by more than the margin.
        return fallback if fallback in q and q[fallback] + self.margin >= q[best] else int(best)


#: The class's name before 0.2.0.
RolloutPlanner = PlannerController
