"""A look-ahead guard against lost vehicles, around any controller (a shield).

The base controller (the dispatcher by default) decides; the guard only vetoes. At a decision
that matters (the acting vehicle on a port, on a charger or hovering, with more than one legal
action) it simulates the base's choice, then the base (or ``fleet``) for the whole fleet, over the next
``horizon_min`` minutes, ``samples`` times, in a copy of the simulator
(:meth:`VertiportSim.snapshot` / :meth:`~VertiportSim.restore`) that draws the config's
uncertainties (wind gusts, charger and take-off failures) from generators of its own:

* if no rollout loses a vehicle (``sim.lost``), the base's choice stands;
* if one does, every legal action of the acting vehicle is simulated the same way
  (``compare_samples`` times each, ``samples`` by default; the first ``samples`` of them draw
  what the check drew), with the same draws for every action (common random numbers). If the
  base's choice loses at least ``min_lost`` vehicles on average over its rollouts (half a
  vehicle by default: a loss in at least half of them), the action with the fewest vehicles
  lost on average is taken: the base's choice where it ties for the fewest, else the one whose
  rollouts earn the most reward (with ``prefer="margin"``: keep the most charge). Such an
  override needs a gain of at least ``min_saved`` vehicles on average (any gain by default),
  and with ``override_takeoff=False`` it never takes off where the base's choice does not.

With ``port_hops=False`` a vehicle on a normal port never taxis to another normal port, a move
the dispatcher never makes (it idles at the ground drain all the way and trades one normal port
for another): such a choice of the base is handed to ``fleet`` (``stay`` without one), and an
override never makes it.

With ``floor_pct`` above 0 the rollouts count a near loss as a loss: a vehicle whose charge falls
below ``floor_pct`` (%) in a rollout, having started it at or above, is counted as lost there, in
the check and in the comparison alike. Four draws of the gusts and failures under-sample the bad
ones; the floor keeps a charge margin for what they miss.

A check that loses no vehicle and in which no live vehicle's charge falls below ``quiet_pct``
lets the guard skip the checks of the next ``quiet_min`` minutes: most of a day is far from a
loss, and the checks cost the rollouts.

With a ``fleet`` of its own, the check asks whether the base's choice loses a vehicle when
``fleet`` decides every turn after it; the base goes on deciding instead, so the check is
optimistic (a base that keeps a low vehicle hovering passes every check while the rollouts land
it at its next turn). ``defer_pct`` closes that gap for the vehicles nearest a loss: an acting
vehicle with less charge than ``defer_pct`` (%) is decided by ``fleet`` itself, then checked as
usual, so that for those vehicles the rollouts follow the controller that will fly them.
``margin_pct`` hands ``fleet`` the decisions whose check is not clean: where a rollout of the
base's choice loses a vehicle or lets a live vehicle's charge fall below ``margin_pct`` (%), the
fleet's own choice is checked instead, so the base decides only while its choice keeps the whole
fleet that far from a loss (and a check is quiet only if it keeps ``margin_pct`` too). Around a
base other than ``fleet``, a quiet check hands the base the next ``quiet_min`` minutes unchecked;
``quiet_pct`` above 100 checks every decision that matters.

``reward_margin`` lets the rollouts choose between the two controllers where they disagree: where
the base's choice passes its check and ``fleet`` would choose otherwise, the fleet's choice is
rolled out with the same draws, and it is taken if it loses no vehicle and its rollouts earn at
least ``reward_margin`` more reward on average. Both are judged with ``fleet`` flying the fleet
after them, so this is one step of policy improvement over ``fleet`` (a rollout algorithm) with
the base's proposal as the only other candidate.

``self_check`` closes the rest of the gap: a base choice that passes the fleet's rollouts is
rolled out ``samples`` more times with the base itself going on deciding (``fleet`` for the
vehicles below ``defer_pct``), as it will once the choice is taken, and it stands only if none of
those rollouts loses a vehicle either; otherwise ``fleet`` decides, checked as usual. The base
must decide from observations (not a look-ahead that reads the simulator); a GCN checkpoint is
rolled out through its stateless greedy copy (``fast()``).

Unlike :class:`agents.controllers.planner.RolloutPlanner`, which replaces the base's choice
whenever another action earns more reward (and under uncertainty loses more vehicles than the
dispatcher, docs/training.md), the guard changes a decision only to lose fewer vehicles, so it
keeps the base's margins everywhere else. It is model-based: it reads the simulator's true
state (bind it with :meth:`GuardedController.bind`, as the episode runners of
:mod:`agents.controllers.episode` do).

``clairvoyant=True`` makes it an oracle for studies, not a controller one could deploy: its
rollouts draw from a copy of the env's own generator, so the rollout of the base's choice is the
day's actual future (the same gusts, failures and flight plans) for as long as the fleet follows
the base. What it cannot save with one changed decision and two hours of exact foresight bounds
what any such look-ahead can save (docs/environment.md, section 8.3).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.controllers.base import Controller
from agents.controllers.planner import ScratchRollouts, nominal_config, roll_out
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT

#: What ``prefer`` may name, and the column of :meth:`GuardedController.evaluate`'s values it
#: maximises among the actions that lose the fewest vehicles.
PREFERRED_COLUMN = {"reward": 1, "margin": 2}


class GuardedController(ScratchRollouts, Controller):
    """The base controller's decisions, changed only where a look-ahead finds that they lose a
    vehicle and another legal action loses fewer.

    Args:
        base: the controller guarded: an agent spec (``"heuristic"``, default) or a controller
            object. Its ``act`` should be cheap: the rollouts call it at every simulated turn.
        horizon_min: minutes simulated per rollout, the decision's own step included.
        samples: rollouts per action; each draws the uncertainties from its own generator (one
            where the config has none).
        compare_samples: rollouts per action where the base's choice lost a vehicle and every
            legal action is compared (at least ``samples``; default ``None``: ``samples``),
            the one comparison that decides a changed decision.
        nominal: roll out without the config's uncertainties (and so once per action).
        quiet_pct: a clean check in which every live vehicle keeps at least this charge (%)
            skips the checks of the next ``quiet_min`` minutes (above 100: never skip).
        quiet_min: minutes of skipped checks after a quiet check.
        min_lost: vehicles the base's choice must lose on average over its rollouts for the
            guard to change it (with one rollout per action, any loss).
        seed: seed of the rollouts' generators, combined with the episode's seed, the step and
            the sample.
        clairvoyant: roll out once per action, from a copy of the env's own generator (the
            module's docstring: an oracle, it sees the future); not with ``nominal``.
        prefer: of the actions that lose the fewest vehicles, take the one whose rollouts earn
            the most reward (``"reward"``) or keep the most charge: the highest mean over its
            rollouts of the least charge of a live vehicle (``"margin"``).
        fleet: the controller that flies the whole fleet in the rollouts after the decision's
            own step: an agent spec or a controller object; default (``None``): ``base``. Set
            it where the base is too slow to roll out (``guard[base=rollout,fleet=heuristic]``,
            ``guard[base=gcn,fleet=heuristic]``): the check then asks whether the base's choice,
            followed by ``fleet``'s decisions, loses a vehicle. A model-based base is bound to
            the env's own simulator, ``fleet`` to the scratch copy.
        defer_pct: with a ``fleet`` of its own, an acting vehicle with less charge than this
            (%) is decided by ``fleet`` instead of the base (0, default: never).
        margin_pct: with a ``fleet`` of its own, a checked decision whose base choice loses a
            vehicle, or lets a live vehicle's charge fall below this (%), in a rollout is
            decided by ``fleet`` instead, then checked as usual (0, default: never).
        self_check: with a ``fleet`` of its own, a base choice that passes the fleet's rollouts
            stands only if ``samples`` rollouts in which the base goes on deciding (``fleet``
            below ``defer_pct``) lose no vehicle either; otherwise ``fleet`` decides, checked
            as usual (default: off).
        min_saved: an override must lose at least this many vehicles fewer on average over its
            rollouts than the base's choice (default 0: any fewer); a smaller gain, within the
            rollouts' noise, leaves the base's choice standing.
        override_takeoff: whether an override may take off where the base's choice does not
            (default: yes); ``False`` keeps every trip the guard starts one the base chose.
        floor_pct: a live vehicle whose charge falls below this (%) in a rollout, having
            started the rollout at or above it, counts as lost in that rollout (0, default: only
            a depleted battery is a loss).
        port_hops: whether a vehicle on a normal port may taxi to another normal port (default:
            yes); ``False`` hands such a choice of the base to ``fleet`` (``stay`` without
            one) and keeps the override from making it.
        reward_margin: with a ``fleet`` of its own, where the base's choice passes its check and
            the fleet's differs, the fleet's is taken if its rollouts (the same draws) lose no
            vehicle and earn at least this much more reward on average (``None``, default:
            never).
    """

    name = "guard"

    def __init__(self, base: str | Any = "heuristic", horizon_min: float = 120.0,
                 samples: int = 4, compare_samples: int | None = None, nominal: bool = False,
                 quiet_pct: float = 20.0,
                 quiet_min: float = 10.0, seed: int = 0, min_lost: float = 0.5,
                 clairvoyant: bool = False, prefer: str = "reward",
                 fleet: str | Any | None = None, defer_pct: float = 0.0,
                 margin_pct: float = 0.0, self_check: bool = False, min_saved: float = 0.0,
                 override_takeoff: bool = True, floor_pct: float = 0.0,
                 port_hops: bool = True, reward_margin: float | None = None) -> None:
        if horizon_min <= 0:
            raise ValueError(f"horizon_min must be > 0 minutes, got {horizon_min}")
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        if compare_samples is not None and compare_samples < samples:
            raise ValueError(f"compare_samples must be >= samples ({samples}), "
                             f"got {compare_samples}")
        if quiet_min < 0:
            raise ValueError(f"quiet_min must be >= 0 minutes, got {quiet_min}")
        if min_lost <= 0:
            raise ValueError(f"min_lost must be > 0 vehicles, got {min_lost}")
        if min_saved < 0:
            raise ValueError(f"min_saved must be >= 0 vehicles, got {min_saved}")
        if clairvoyant and nominal:
            raise ValueError("clairvoyant rollouts draw the env's own future: they cannot also "
                             "be nominal (without the config's uncertainties)")
        if prefer not in PREFERRED_COLUMN:
            raise ValueError(f"prefer must be one of {sorted(PREFERRED_COLUMN)}, got {prefer!r}")
        for name, pct in (("defer_pct", defer_pct), ("margin_pct", margin_pct),
                          ("floor_pct", floor_pct)):
            if not 0.0 <= pct <= 100.0:
                raise ValueError(f"{name} must be a charge in [0, 100] %, got {pct}")
        for name, pct in (("defer_pct", defer_pct), ("margin_pct", margin_pct)):
            if pct > 0 and fleet is None:
                raise ValueError(f"{name} hands decisions to fleet: it needs a fleet of its "
                                 f"own (e.g. guard[base=gcn,fleet=heuristic,{name}=30])")
        if reward_margin is not None and fleet is None:
            raise ValueError("reward_margin weighs the base's choice against fleet's: it needs a "
                             "fleet of its own (e.g. guard[base=gcn,fleet=heuristic,"
                             "reward_margin=0])")
        if self_check and fleet is None:
            raise ValueError("self_check rolls the base out beside fleet: it needs a fleet of "
                             "its own (e.g. guard[base=gcn,fleet=heuristic,self_check=true])")
        from agents.controllers.registry import make_controller

        if isinstance(base, str):
            base = make_controller(base)
        if isinstance(fleet, str):
            fleet = make_controller(fleet)
        if self_check and isinstance(base, ScratchRollouts):
            raise ValueError(f"self_check rolls the base out in a scratch copy: a look-ahead "
                             f"that reads the env's simulator ({type(base).__name__}) cannot be")
        self.base = base
        #: The rollouts' controller (``fleet``); ``None``: the base.
        self.fleet = fleet
        self.horizon_min = float(horizon_min)
        self.samples = int(samples)
        self.compare_samples = self.samples if compare_samples is None else int(compare_samples)
        self.nominal = bool(nominal)
        self.quiet_pct = float(quiet_pct)
        self.quiet_min = float(quiet_min)
        self.seed = int(seed)
        self.min_lost = float(min_lost)
        self.min_saved = float(min_saved)
        self.override_takeoff = bool(override_takeoff)
        self.floor_pct = float(floor_pct)
        self.port_hops = bool(port_hops)
        self.reward_margin = None if reward_margin is None else float(reward_margin)
        #: This episode's decisions where the fleet's choice earned more in the rollouts
        #: (``reward_margin``) and was taken.
        self.contests_won = 0
        self.clairvoyant = bool(clairvoyant)
        self.prefer = prefer
        self.defer_pct = float(defer_pct)
        self.margin_pct = float(margin_pct)
        #: The continuation of the self-check (``self_check``): the base (its fast copy where it
        #: has one) deciding, ``fleet`` below ``defer_pct``; ``None`` without the check.
        self.onward = (_Onward(getattr(base, "fast", lambda: base)(), fleet, self.defer_pct)
                       if self_check else None)
        self._episode_seed = 0
        self._runs = self.samples
        self._compare_runs = self.compare_samples
        self._quiet_until_step = -1
        #: Per action of the last decision that ran the full comparison: (mean vehicles lost,
        #: mean reward, mean least charge %) over its rollouts; empty where the base's choice
        #: stood unchallenged.
        self.last_values: dict[int, tuple[float, float, float]] = {}
        #: This episode's decisions checked by rollouts, decisions changed, and decisions
        #: handed to ``fleet`` (``defer_pct``, ``margin_pct``).
        self.checks = 0
        self.changes = 0
        self.deferrals = 0
        #: Whether the last decision was changed (the base's choice lost a vehicle).
        self.last_changed = False
        #: Whether ``fleet`` took the last decision instead of the base (``defer_pct``,
        #: ``margin_pct``).
        self.last_deferred = False

    # ------------------------------------------------------------------ episode
    def reset(self, seed: int | None = None) -> None:
        self._episode_seed = 0 if seed is None else int(seed)
        self._quiet_until_step = -1
        self.last_values = {}
        self.checks = self.changes = self.deferrals = self.contests_won = 0
        self.last_changed = self.last_deferred = False
        for policy in self._policies():
            if hasattr(policy, "reset"):
                policy.reset(seed=seed)

    @property
    def rollout_policy(self) -> Any:
        """The controller that flies the fleet in the rollouts: ``fleet``, else ``base``."""
        return self.base if self.fleet is None else self.fleet

    def _policies(self) -> list[Any]:
        return [self.base] if self.fleet is None else [self.base, self.fleet]

    def bind(self, sim: VertiportSim) -> None:
        """Guard the env whose simulator is ``sim`` (:class:`ScratchRollouts`); a config
        without uncertainties, ``nominal`` or ``clairvoyant``, is rolled out once per action.
        With a ``fleet`` of its own, a model-based base decides on ``sim`` itself."""
        super().bind(sim)
        if self.fleet is not None and hasattr(self.base, "bind"):
            self.base.bind(sim)
        if self.onward is not None:
            self.onward.sim = self._scratch
        cfg = self._scratch.cfg
        # Without uncertainties every rollout of an action is the same: one is enough.
        alike = self.clairvoyant or cfg == nominal_config(cfg)
        self._runs = 1 if alike else self.samples
        self._compare_runs = 1 if alike else self.compare_samples

    def close(self) -> None:
        super().close()
        for policy in self._policies():
            if hasattr(policy, "close"):
                policy.close()

    # ------------------------------------------------------------------ rollouts
    def horizon_steps(self, sim: VertiportSim) -> int:
        """Steps a rollout simulates: ``horizon_min`` in the env's minutes per step (at least 1)."""
        return max(1, int(round(self.horizon_min / sim.cfg.schedule.minutes_per_step)))

    def evaluate(self, sim: VertiportSim, actions: list[int],
                 stop_at_loss: bool = False, policy: Any = None, runs: int | None = None
                 ) -> tuple[dict[int, tuple[float, float, float]], float]:
        """Per action, the mean over its rollouts of the vehicles lost (beyond those already
        lost; with ``floor_pct``, also those whose charge fell below it), of the reward and of
        the least charge (%) of a live vehicle in the rollout; and the least charge (%) of a
        live vehicle seen in any rollout step. ``stop_at_loss``: stop
        an action's rollouts at the first that loses a vehicle (its means are then over the
        rollouts run). ``policy`` flies the rollouts (default: :attr:`rollout_policy`);
        ``runs`` rollouts per action (default: ``samples``, one where they are all alike)."""
        policy = self.rollout_policy if policy is None else policy
        runs_per_action = self._runs if runs is None else int(runs)
        scratch, builder = self._scratch, self._builder
        assert scratch is not None and builder is not None
        snap = sim.snapshot()
        steps = self.horizon_steps(sim)
        lost_before = int(np.count_nonzero(sim.lost))
        run_least = [100.0]
        # The vehicles the floor watches (live and at or above it now), and those of them that
        # fell below it in the current rollout.
        floored = ~sim.lost & (sim.battery >= self.floor_pct) if self.floor_pct > 0 else None
        below = np.zeros(sim.lost.shape, dtype=bool)

        def watch(s: VertiportSim) -> None:
            live = ~s.lost
            if live.any():
                run_least[0] = min(run_least[0], float(s.battery[live].min()))
            if floored is not None:
                below[floored & live & (s.battery < self.floor_pct)] = True

        least = 100.0
        values: dict[int, tuple[float, float, float]] = {}
        for a in actions:
            lost = reward = margin = 0.0
            played = 0
            for k in range(runs_per_action):
                rng = None if self.clairvoyant else np.random.default_rng(
                    (self.seed, self._episode_seed, sim.step_count, k))
                run_least[0] = 100.0
                below[:] = False
                reward += roll_out(scratch, builder, policy, snap, a, steps, rng, watch)
                lost += int(np.count_nonzero(scratch.lost | below)) - lost_before
                margin += run_least[0]
                least = min(least, run_least[0])
                played += 1
                if stop_at_loss and lost > 0:
                    break
            values[a] = (lost / played, reward / played, margin / played)
        return values, least

    # ------------------------------------------------------------------ decisions
    @property
    def last_q(self) -> dict[int, float]:
        """For a teacher (:mod:`agents.training.imitation`): the base's values of the
        candidates of the last decision, where the base took it and its choice stood (empty
        otherwise or if the base has none)."""
        if self.last_changed or self.last_deferred:
            return {}
        return dict(getattr(self.base, "last_q", {}) or {})

    @property
    def last_forced(self) -> bool:
        """Whether the last decision ruled a legal action out as unsafe: the guard changed the
        base's choice, which lost a vehicle (or the base itself ruled one out)."""
        return self.last_changed or bool(getattr(self.base, "last_forced", False))

    def action_probabilities(self, observation: dict) -> np.ndarray | None:
        """The base's probabilities (the learned policy's proposal, for the decision log), or
        ``None`` where the base has none."""
        fn = getattr(self.base, "action_probabilities", None)
        return None if fn is None else fn(observation)

    def _fleet_decides(self, observation: dict) -> int:
        """``fleet``'s choice for the acting vehicle, counted as a decision handed over."""
        self.last_deferred = True
        self.deferrals += 1
        return int(self.fleet.act(observation))

    def _contest(self, sim: VertiportSim, observation: dict, choice: int,
                 first: dict[int, tuple[float, float, float]], least: float
                 ) -> tuple[int, dict[int, tuple[float, float, float]], float]:
        """``reward_margin``: the base's clean ``choice`` (its rollout values ``first``, the least
        charge ``least``) against the fleet's own choice, rolled out with the same draws; the
        fleet's, with its values and least charge, where it loses no vehicle and earns at least
        ``reward_margin`` more, else the base's unchanged."""
        own = int(self.fleet.act(observation))
        if own == choice or own in self._hops(sim, sim.acting):
            return choice, first, least
        theirs, their_least = self.evaluate(sim, [own], stop_at_loss=True)
        if theirs[own][0] > 0 or theirs[own][1] < first[choice][1] + self.reward_margin:
            return choice, first, least
        self.last_deferred = True
        self.deferrals += 1
        self.contests_won += 1
        return own, theirs, their_least

    def _hops(self, sim: VertiportSim, v: int) -> set[int]:
        """The actions that taxi vehicle ``v`` from a normal port to another normal port, where
        ``port_hops`` rules them out (empty otherwise)."""
        if self.port_hops or sim.status[v] != ON_PORT:
            return set()
        return {sim.actions.node_action(k) for k in range(sim.layout.n_normal)}

    def act(self, observation: dict) -> int:
        sim = self.sim
        if sim is None:
            raise RuntimeError("GuardedController needs the simulator: call bind(env.unwrapped.sim) "
                               "first (the episode runners of agents.controllers.episode do)")
        v = sim.acting
        self.last_deferred = False
        if self.defer_pct > 0 and sim.battery[v] < self.defer_pct:
            choice = self._fleet_decides(observation)
        else:
            choice = int(self.base.act(observation))
        hops = self._hops(sim, v)
        if choice in hops:  # a taxi from a normal port to another: fleet decides, or stay
            if self.fleet is not None:
                choice = self._fleet_decides(observation)
            if choice in hops:
                choice = sim.actions.stay
        self.last_values = {}
        self.last_changed = False
        if sim.status[v] not in (ON_PORT, ON_CHARGER, HOVERING) or sim.step_count < self._quiet_until_step:
            return choice
        if not np.array_equal(observation["action_mask"], sim.action_mask(v)):
            raise RuntimeError("GuardedController: the observation is not that of the bound env's "
                               "acting vehicle")
        legal = np.flatnonzero(observation["action_mask"]).tolist()
        if len(legal) < 2:
            return choice
        self.checks += 1
        first, least = self.evaluate(sim, [choice], stop_at_loss=True)
        if self.margin_pct > 0 and not self.last_deferred and (
                first[choice][0] > 0 or least < self.margin_pct):
            own = self._fleet_decides(observation)  # not clean for margin_pct; checked as usual
            if own != choice:
                choice = own
                first, least = self.evaluate(sim, [choice], stop_at_loss=True)
        if first[choice][0] == 0 and self.onward is not None and not self.last_deferred:
            onward, _ = self.evaluate(sim, [choice], stop_at_loss=True, policy=self.onward)
            if onward[choice][0] > 0:  # the base, going on deciding, loses one: fleet decides
                own = self._fleet_decides(observation)
                if own != choice:
                    choice = own
                    first, least = self.evaluate(sim, [choice], stop_at_loss=True)
        if first[choice][0] == 0:
            if self.reward_margin is not None and not self.last_deferred:
                choice, first, least = self._contest(sim, observation, choice, first, least)
            if least >= max(self.quiet_pct, self.margin_pct):
                self._quiet_until_step = sim.step_count + int(
                    round(self.quiet_min / sim.cfg.schedule.minutes_per_step))
            return choice
        # The actions an override may pick: every legal one, but a take-off the base's choice
        # did not make where overrides may not take off, and a taxi to another normal port
        # where those are ruled out.
        eligible = [a for a in legal if a == choice or (
            self.override_takeoff or a != sim.actions.takeoff) and a not in hops]
        values, _ = self.evaluate(sim, eligible if choice in eligible else [*eligible, choice],
                                  runs=self._compare_runs)
        self.last_values = values
        fewest = min(v[0] for v in values.values())
        saved = values[choice][0] - fewest
        if saved <= 0 or saved < self.min_saved or values[choice][0] < self.min_lost:
            return choice
        col = PREFERRED_COLUMN[self.prefer]
        best = max((a for a in values if values[a][0] <= fewest), key=lambda a: values[a][col])
        self.changes += 1
        self.last_changed = True
        return int(best)


class _Onward:
    """The self-check's continuation: ``policy`` decides for every vehicle but those with less
    charge than ``defer_pct`` (%), which ``fleet`` decides, as the guard will after the checked
    turn (short of its own checks). ``sim`` is the scratch copy the rollouts run in."""

    def __init__(self, policy: Any, fleet: Any, defer_pct: float) -> None:
        self.policy, self.fleet, self.defer_pct = policy, fleet, defer_pct
        self.pure_act = bool(getattr(policy, "pure_act", False) and getattr(fleet, "pure_act", False))
        self.sim: VertiportSim | None = None

    def act(self, observation: dict) -> int:
        sim = self.sim
        if self.defer_pct > 0 and sim.battery[sim.acting] < self.defer_pct:
            return int(self.fleet.act(observation))
        return int(self.policy.act(observation))
