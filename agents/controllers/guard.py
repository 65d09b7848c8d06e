"""A look-ahead around any controller: ``guard`` (veto only) and the engine of ``lookahead``.

The proposer (the dispatcher by default) decides; the look-ahead checks. At a decision that
matters (the acting vehicle on a port, on a charger or hovering, with more than one legal
action) it simulates the proposer's choice, then the rollout policy (the proposer itself by
default) flying the whole fleet, over the next ``horizon_min`` minutes, ``samples`` times, in a
copy of the simulator (:meth:`VertiportSim.snapshot` / :meth:`~VertiportSim.restore`) that draws
the config's uncertainties (wind gusts, charger and take-off failures) from generators of its
own. Each such simulated continuation is a *rollout*.

* if no rollout loses a vehicle (``sim.lost``), the proposer's choice stands;
* if one does, every legal action of the acting vehicle is rolled out the same way
  (``compare_samples`` times each, ``samples`` by default; the first ``samples`` of them draw
  what the check drew), with the same draws for every action (common random numbers). If the
  proposer's choice loses at least ``min_lost`` vehicles on average over its rollouts (half a
  vehicle by default: a loss in at least half of them), the action with the fewest vehicles
  lost on average is taken: the proposer's choice where it ties for the fewest, else the one
  whose rollouts earn the most reward (with ``prefer="margin"``: keep the most charge). Such an
  override needs a gain of at least ``min_saved`` vehicles on average (any gain by default),
  and with ``override_takeoff=False`` it never takes off where the proposer's choice does not.

The settings are a :class:`~agents.controllers.lookahead_settings.LookaheadSettings` (every
field documented there) with two presets: ``guard`` (the defaults above: veto only) and
``lookahead`` (:mod:`agents.controllers.lookahead`).

With ``port_hops=False`` a vehicle on a normal port never taxis to another normal port, a move
the dispatcher never makes (it idles at the ground drain all the way and trades one normal port
for another): such a choice of the proposer is handed to the rollout policy (``stay`` without
one of its own), and an override never makes it.

With ``floor_pct`` above 0 the rollouts count a near loss as a loss: a vehicle whose charge falls
below ``floor_pct`` (%) in a rollout, having started it at or above, is counted as lost there, in
the check and in the comparison alike. Four draws of the gusts and failures under-sample the bad
ones; the floor keeps a charge margin for what they miss.

A check that loses no vehicle and in which no live vehicle's charge falls below ``quiet_pct``
lets the look-ahead skip the checks of the next ``quiet_min`` minutes: most of a day is far from
a loss, and the checks cost the rollouts.

With a ``rollout_policy`` of its own, the check asks whether the proposer's choice loses a
vehicle when the rollout policy decides every turn after it; the proposer goes on deciding
instead, so the check is optimistic (a proposer that keeps a low vehicle hovering passes every
check while the rollouts land it at its next turn). ``defer_pct`` closes that gap for the
vehicles nearest a loss: an acting vehicle with less charge than ``defer_pct`` (%) is decided by
the rollout policy itself, then checked as usual, so that for those vehicles the rollouts follow
the controller that will fly them. ``margin_pct`` hands the rollout policy the decisions whose
check is not clean: where a rollout of the proposer's choice loses a vehicle or lets a live
vehicle's charge fall below ``margin_pct`` (%), the rollout policy's own choice is checked
instead, so the proposer decides only while its choice keeps the whole fleet that far from a
loss (and a check is quiet only if it keeps ``margin_pct`` too). Around a proposer other than
the rollout policy, a quiet check hands the proposer the next ``quiet_min`` minutes unchecked;
``quiet_pct`` above 100 checks every decision that matters.

``reward_margin`` lets the rollouts choose between the two controllers where they disagree:
where the proposer's choice passes its check and the rollout policy would choose otherwise, the
rollout policy's choice is rolled out with the same draws, and it is taken if it loses no vehicle
and its rollouts earn at least ``reward_margin`` more reward on average. Both are judged with the
rollout policy flying the fleet after them, so this is one step of policy improvement over the
rollout policy (a rollout algorithm) with the proposer's choice as the only other candidate.

``self_check`` closes the rest of the gap: a proposer's choice that passes the rollout policy's
rollouts is rolled out ``samples`` more times with the proposer itself going on deciding (the
rollout policy for the vehicles below ``defer_pct``), as it will once the choice is taken, and it
stands only if none of those rollouts loses a vehicle either; otherwise the rollout policy
decides, checked as usual. The proposer must decide from observations (not a look-ahead that
reads the simulator); a GCN checkpoint is rolled out through its stateless greedy copy
(``fast()``).

Unlike :class:`agents.controllers.planner.PlannerController`, which replaces the dispatcher's
choice whenever another action earns more reward (and under uncertainty loses more vehicles than
the dispatcher), the guard changes a decision only to lose fewer vehicles, so it keeps the
proposer's margins everywhere else. It is model-based: it reads the simulator's true state (bind
it with :meth:`GuardController.bind`, as the episode runners of
:mod:`agents.controllers.episode` do).

``clairvoyant=True`` makes it an oracle for studies, not a controller one could deploy: its
rollouts draw from a copy of the env's own generator, so the rollout of the proposer's choice is
the day's actual future (the same gusts, failures and flight plans) for as long as the fleet
follows the proposer. What it cannot save with one changed decision and two hours of exact
foresight bounds what any such look-ahead can save.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.common.names import canonical_kwargs, note_renamed
from agents.controllers.base import Controller
from agents.controllers.lookahead_settings import PREFERRED_COLUMN, LookaheadSettings
from agents.controllers.planner import (ScratchRollouts, held_terms_value, nominal_config,
                                        roll_out)
from agents.controllers.search import wide_choice
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT

__all__ = ["GuardController", "GuardedController", "PREFERRED_COLUMN"]

#: An argument not given (the class's default applies).
_DEFAULT: Any = object()


class GuardController(ScratchRollouts, Controller):
    """The proposer's decisions, changed only where a look-ahead finds that they lose a vehicle
    and another legal action loses fewer (with the ``guard`` preset; the module docstring).

    Args:
        proposer: the controller whose choices are checked: an agent spec (default
            ``"dispatcher"``) or a controller object. Its ``act`` should be cheap where it also
            flies the rollouts.
        rollout_policy: the controller that flies the whole fleet in the rollouts after the
            decision's own step: an agent spec or a controller object; ``None`` (default): the
            proposer. Set it where the proposer is too slow to roll out
            (``guard[proposer=planner,rollout_policy=dispatcher]``); the check then asks whether
            the proposer's choice, followed by the rollout policy's decisions, loses a vehicle.
            A model-based proposer is bound to the env's own simulator, the rollout policy to
            the scratch copy.
        settings: a :class:`LookaheadSettings` or the name of a preset (default: the class's,
            ``"guard"``).
        **changes: fields of ``settings`` to change (``horizon_min=60``: a spec's arguments),
            and ``base`` / ``fleet``, the names of ``proposer`` / ``rollout_policy`` before
            0.2.0 (with a note).
    """

    name = "guard"
    #: The preset the settings start from.
    preset = "guard"
    #: The defaults of ``proposer`` and ``rollout_policy``.
    default_proposer: Any = "dispatcher"
    default_rollout_policy: Any = None

    def __init__(self, proposer: str | Any = _DEFAULT, rollout_policy: str | Any = _DEFAULT,
                 settings: LookaheadSettings | str | None = None, **changes: Any) -> None:
        changes = canonical_kwargs(self.name, changes)
        for key, given in (("proposer", proposer), ("rollout_policy", rollout_policy)):
            if key in changes and given is not _DEFAULT:
                raise TypeError(f"{type(self).__name__}: {key} given twice (once by its old name)")
        proposer = changes.pop("proposer", proposer)
        rollout_policy = changes.pop("rollout_policy", rollout_policy)
        proposer = self.default_proposer if proposer is _DEFAULT else proposer
        rollout_policy = self.default_rollout_policy if rollout_policy is _DEFAULT else rollout_policy
        if settings is None or isinstance(settings, str):
            settings = LookaheadSettings.preset(settings or self.preset)
        settings = settings.replace(**changes) if changes else settings
        settings.check_rollout_policy(rollout_policy is not None)
        from agents.controllers.registry import make_controller

        if isinstance(proposer, str):
            proposer = make_controller(proposer)
        if isinstance(rollout_policy, str):
            rollout_policy = make_controller(rollout_policy)
        if settings.self_check and isinstance(proposer, ScratchRollouts):
            raise ValueError(f"self_check rolls the proposer out in a scratch copy: a look-ahead "
                             f"that reads the env's simulator ({type(proposer).__name__}) cannot be")
        #: The settings (:class:`LookaheadSettings`).
        self.settings = settings
        self.proposer = proposer
        #: The rollout policy given of its own; ``None``: the proposer flies the rollouts.
        self.own_rollout_policy = rollout_policy
        #: The continuation of the self-check (``self_check``): the proposer (its fast copy
        #: where it has one) deciding, the rollout policy below ``defer_pct``; ``None`` without
        #: the check.
        self.onward = (_Onward(getattr(proposer, "fast", lambda: proposer)(), rollout_policy,
                               settings.defer_pct) if settings.self_check else None)
        self._episode_seed = 0
        self._runs = settings.samples
        self._compare_runs = self.compare_samples
        self._quiet_until_step = -1
        #: Per action of the last decision that ran the full comparison: (mean vehicles lost,
        #: mean reward, mean least charge %) over its rollouts; empty where the proposer's
        #: choice stood unchallenged.
        self.last_values: dict[int, tuple[float, float, float]] = {}
        #: The wide search's value of each candidate of its last decision (reward less
        #: :data:`~agents.controllers.search.LOSS_COST` per vehicle lost, on average).
        self.search_q: dict[int, float] = {}
        #: The two candidates of the last decision's reward contest (``reward_margin``), the
        #: proposer's choice and the rollout policy's, each as in :attr:`last_values`; empty
        #: where there was none.
        self.last_contest: dict[int, tuple[float, float, float]] = {}
        #: Per action of the last :meth:`evaluate`: each rollout's (vehicles lost, reward).
        self.last_runs: dict[int, list[tuple[float, float]]] = {}
        #: This episode's decisions checked by rollouts, decisions changed, decisions handed to
        #: the rollout policy (``defer_pct``, ``margin_pct``, ``reward_margin``), and those of
        #: them where the rollout policy's choice earned more in the rollouts
        #: (``reward_margin``).
        self.checks = self.changes = self.deferrals = self.contests_won = 0
        #: Whether the last decision was changed (the proposer's choice lost a vehicle).
        self.last_changed = False
        #: Whether the rollout policy took the last decision instead of the proposer.
        self.last_deferred = False

    @property
    def nominal(self) -> bool:
        """Whether the rollouts run without the config's uncertainties (:class:`ScratchRollouts`)."""
        return self.settings.nominal

    @property
    def compare_samples(self) -> int:
        """Rollouts per action in the full comparison."""
        s = self.settings
        return s.samples if s.compare_samples is None else int(s.compare_samples)

    @property
    def base(self) -> Any:
        """The name of :attr:`proposer` before 0.2.0."""
        note_renamed("base", "proposer", f"{self.name} attribute")
        return self.proposer

    @property
    def fleet(self) -> Any:
        """The name of :attr:`own_rollout_policy` before 0.2.0."""
        note_renamed("fleet", "own_rollout_policy", f"{self.name} attribute")
        return self.own_rollout_policy

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
        """The controller that flies the fleet in the rollouts: :attr:`own_rollout_policy`,
        else the proposer."""
        return self.proposer if self.own_rollout_policy is None else self.own_rollout_policy

    def _policies(self) -> list[Any]:
        own = self.own_rollout_policy
        return [self.proposer] if own is None else [self.proposer, own]

    def bind(self, sim: VertiportSim) -> None:
        """Look ahead in the env whose simulator is ``sim`` (:class:`ScratchRollouts`); a
        config without uncertainties, ``nominal`` or ``clairvoyant``, is rolled out once per
        action. With a rollout policy of its own, a model-based proposer decides on ``sim``
        itself."""
        super().bind(sim)
        if self.own_rollout_policy is not None and hasattr(self.proposer, "bind"):
            self.proposer.bind(sim)
        if self.onward is not None:
            self.onward.sim = self._scratch
        cfg = self._scratch.cfg
        # Without uncertainties every rollout of an action is the same: one is enough.
        alike = self.settings.clairvoyant or cfg == nominal_config(cfg)
        self._runs = 1 if alike else self.settings.samples
        self._compare_runs = 1 if alike else self.compare_samples

    def close(self) -> None:
        super().close()
        for policy in self._policies():
            if hasattr(policy, "close"):
                policy.close()

    # ------------------------------------------------------------------ rollouts
    def horizon_steps(self, sim: VertiportSim) -> int:
        """Steps a rollout simulates: ``horizon_min`` in the env's minutes per step (at least 1)."""
        return max(1, int(round(self.settings.horizon_min / sim.cfg.schedule.minutes_per_step)))

    def evaluate(self, sim: VertiportSim, actions: list[int],
                 stop_at_loss: bool = False, policy: Any = None, runs: int | None = None
                 ) -> tuple[dict[int, tuple[float, float, float]], float]:
        """Per action, the mean over its rollouts of the vehicles lost (beyond those already
        lost; with ``floor_pct``, also those whose charge fell below it), of the reward (with
        ``leaf_turns``, plus the value of the rollout's end state) and of
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
        floor_pct = self.settings.floor_pct
        floored = ~sim.lost & (sim.battery >= floor_pct) if floor_pct > 0 else None
        below = np.zeros(sim.lost.shape, dtype=bool)

        def watch(s: VertiportSim) -> None:
            live = ~s.lost
            if live.any():
                run_least[0] = min(run_least[0], float(s.battery[live].min()))
            if floored is not None:
                below[floored & live & (s.battery < floor_pct)] = True

        least = 100.0
        leaf_turns = self.settings.leaf_turns
        values: dict[int, tuple[float, float, float]] = {}
        self.last_runs = {}
        for a in actions:
            lost = reward = margin = 0.0
            played = 0
            runs = self.last_runs[a] = []
            for k in range(runs_per_action):
                rng = None if self.settings.clairvoyant else np.random.default_rng(
                    (self.settings.seed, self._episode_seed, sim.step_count, k))
                run_least[0] = 100.0
                below[:] = False
                run_reward = roll_out(scratch, builder, policy, snap, a, steps, rng, watch)
                if leaf_turns > 0:
                    run_reward += held_terms_value(scratch, leaf_turns)
                run_lost = int(np.count_nonzero(scratch.lost | below)) - lost_before
                runs.append((float(run_lost), run_reward))
                reward += run_reward
                lost += run_lost
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
        """For a teacher (:mod:`agents.training.imitation`): the values of the candidates of the
        last decision. The wide search's own (:func:`agents.controllers.search.wide_choice`);
        else the proposer's, where the proposer took it and its choice stood (empty otherwise
        or if the proposer has none)."""
        if self.settings.candidates > 0:
            return dict(self.search_q)
        if self.last_changed or self.last_deferred:
            return {}
        return dict(getattr(self.proposer, "last_q", {}) or {})

    @property
    def last_forced(self) -> bool:
        """Whether the last decision ruled a legal action out as unsafe: the look-ahead changed
        the proposer's choice, which lost a vehicle (or the proposer itself ruled one out)."""
        if self.settings.candidates > 0:  # the wide search: a candidate lost more than another
            lost = [v[0] for v in self.last_values.values()]
            return bool(lost) and max(lost) > min(lost)
        return self.last_changed or bool(getattr(self.proposer, "last_forced", False))

    def action_probabilities(self, observation: dict) -> np.ndarray | None:
        """The proposer's probabilities (the learned policy's proposal, for the decision log),
        or ``None`` where the proposer has none."""
        fn = getattr(self.proposer, "action_probabilities", None)
        return None if fn is None else fn(observation)

    def _handed_over(self, observation: dict) -> int:
        """The rollout policy's choice for the acting vehicle, counted as a decision handed
        over."""
        self.last_deferred = True
        self.deferrals += 1
        return int(self.own_rollout_policy.act(observation))

    def _contest(self, sim: VertiportSim, observation: dict, choice: int,
                 first: dict[int, tuple[float, float, float]], least: float
                 ) -> tuple[int, dict[int, tuple[float, float, float]], float]:
        """``reward_margin``: the proposer's clean ``choice`` (its rollout values ``first``, the
        least charge ``least``) against the rollout policy's own choice, rolled out with the
        same draws; the latter, with its values and least charge, where it loses no vehicle and
        earns at least ``reward_margin`` more, else the proposer's unchanged."""
        own = int(self.own_rollout_policy.act(observation))
        if own == choice or own in self._hops(sim, sim.acting):
            return choice, first, least
        theirs, their_least = self.evaluate(sim, [own], stop_at_loss=True)
        self.last_contest = {choice: first[choice], own: theirs[own]}
        if theirs[own][0] > 0 or theirs[own][1] < first[choice][1] + self.settings.reward_margin:
            return choice, first, least
        self.last_deferred = True
        self.deferrals += 1
        self.contests_won += 1
        return own, theirs, their_least

    def _hops(self, sim: VertiportSim, v: int) -> set[int]:
        """The actions that taxi vehicle ``v`` from a normal port to another normal port, where
        ``port_hops`` rules them out (empty otherwise)."""
        if self.settings.port_hops or sim.status[v] != ON_PORT:
            return set()
        return {sim.actions.node_action(k) for k in range(sim.layout.n_normal)}

    def act(self, observation: dict) -> int:
        sim = self.sim
        if sim is None:
            raise RuntimeError(f"{type(self).__name__} needs the simulator: call "
                               "bind(env.unwrapped.sim) first (the episode runners of "
                               "agents.controllers.episode do)")
        s = self.settings
        v = sim.acting
        self.last_deferred = False
        if s.defer_pct > 0 and sim.battery[v] < s.defer_pct:
            choice = self._handed_over(observation)
        else:
            choice = int(self.proposer.act(observation))
        hops = self._hops(sim, v)
        if choice in hops:  # a taxi from a normal port to another: handed over, or stay
            if self.own_rollout_policy is not None:
                choice = self._handed_over(observation)
            if choice in hops:
                choice = sim.actions.stay
        self.last_values, self.search_q, self.last_contest = {}, {}, {}
        self.last_changed = False
        if sim.status[v] not in (ON_PORT, ON_CHARGER, HOVERING) or sim.step_count < self._quiet_until_step:
            return choice
        if not np.array_equal(observation["action_mask"], sim.action_mask(v)):
            raise RuntimeError(f"{type(self).__name__}: the observation is not that of the bound "
                               "env's acting vehicle")
        legal = np.flatnonzero(observation["action_mask"]).tolist()
        if len(legal) < 2:
            return choice
        if s.candidates > 0:
            return wide_choice(self, sim, observation, legal)
        self.checks += 1
        first, least = self.evaluate(sim, [choice], stop_at_loss=True)
        if s.margin_pct > 0 and not self.last_deferred and (
                first[choice][0] > 0 or least < s.margin_pct):
            own = self._handed_over(observation)  # not clean for margin_pct; checked as usual
            if own != choice:
                choice = own
                first, least = self.evaluate(sim, [choice], stop_at_loss=True)
        if first[choice][0] == 0 and self.onward is not None and not self.last_deferred:
            onward, _ = self.evaluate(sim, [choice], stop_at_loss=True, policy=self.onward)
            if onward[choice][0] > 0:  # the proposer, going on deciding, loses one: hand over
                own = self._handed_over(observation)
                if own != choice:
                    choice = own
                    first, least = self.evaluate(sim, [choice], stop_at_loss=True)
        if first[choice][0] == 0:
            if s.reward_margin is not None and not self.last_deferred:
                choice, first, least = self._contest(sim, observation, choice, first, least)
            if least >= max(s.quiet_pct, s.margin_pct):
                self._quiet_until_step = sim.step_count + int(
                    round(s.quiet_min / sim.cfg.schedule.minutes_per_step))
            return choice
        # The actions an override may pick: every legal one, but a take-off the proposer's choice
        # did not make where overrides may not take off, and a taxi to another normal port
        # where those are ruled out.
        eligible = [a for a in legal if a == choice or (
            s.override_takeoff or a != sim.actions.takeoff) and a not in hops]
        values, _ = self.evaluate(sim, eligible if choice in eligible else [*eligible, choice],
                                  runs=self._compare_runs)
        self.last_values = values
        fewest = min(v[0] for v in values.values())
        saved = values[choice][0] - fewest
        if saved <= 0 or saved < s.min_saved or values[choice][0] < s.min_lost:
            return choice
        col = PREFERRED_COLUMN[s.prefer]
        best = max((a for a in values if values[a][0] <= fewest), key=lambda a: values[a][col])
        self.changes += 1
        self.last_changed = True
        return int(best)


class _Onward:
    """The self-check's continuation: ``policy`` decides for every vehicle but those with less
    charge than ``defer_pct`` (%), which ``rollout_policy`` decides, as the look-ahead will
    after the checked turn (short of its own checks). ``sim`` is the scratch copy the rollouts
    run in."""

    def __init__(self, policy: Any, rollout_policy: Any, defer_pct: float) -> None:
        self.policy, self.rollout_policy, self.defer_pct = policy, rollout_policy, defer_pct
        self.pure_act = bool(getattr(policy, "pure_act", False)
                             and getattr(rollout_policy, "pure_act", False))
        self.sim: VertiportSim | None = None

    def act(self, observation: dict) -> int:
        sim = self.sim
        if self.defer_pct > 0 and sim.battery[sim.acting] < self.defer_pct:
            return int(self.rollout_policy.act(observation))
        return int(self.policy.act(observation))


#: The class's name before 0.2.0.
GuardedController = GuardController
