"""The look-ahead guard: it leaves the real env untouched, acts legally, keeps the base's choice
unless that choice loses a vehicle, and then takes an action that loses fewer."""

import numpy as np
import pytest

from agents.controllers.base import HOVER_SPOT, HOVERING, Observation
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.episode import run_episode
from agents.controllers.guard import GuardController
from agents.controllers.registry import make_controller
from helpers import FixedAction, dispatcher_decision, guarded_actions
from marl_vertiport import vertiport_v1
from marl_vertiport.gym_env import VertiportEnv
from marl_vertiport.sim.schema import ON_CHARGER, ON_PORT
from marl_vertiport.spaces import ObservationBuilder


class _KeepsHolding(DispatcherController):
    """The dispatcher, except that a hovering vehicle moves on to a hover spot whenever one is
    legal: it holds until the energy check forces it down, short of charge, and the fleet
    loses vehicles the dispatcher would keep."""

    def act(self, observation: dict) -> int:
        obs = Observation(observation)
        if obs.status == HOVERING:
            for node in np.flatnonzero(obs.ports("type") == HOVER_SPOT):
                if obs.mask[obs.go_to(node)]:
                    return obs.go_to(node)
        return super().act(observation)


def _dispatcher_day_to_a_choice(env, min_legal: int):
    """Day 0 of ``env`` flown by the dispatcher up to a decision of a vehicle on a port, on a
    charger or hovering with at least ``min_legal`` legal actions: (the dispatcher, bound to
    the simulator; that decision's observation; its legal actions)."""
    dispatcher, obs, _, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        len(legal) >= min_legal and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)))
    return dispatcher, obs, legal


def test_guard_keeps_the_vehicles_its_base_loses():
    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 240})
    lost = {"base": 0, "guard": 0}
    changes = 0
    for seed in range(3):
        lost["base"] += run_episode(env, _KeepsHolding(), seed=seed)["stranded"]
        guard = GuardController(proposer=_KeepsHolding(), horizon_min=30, nominal=True)
        lost["guard"] += run_episode(env, guard, seed=seed)["stranded"]
        changes += guard.changes
        guard.close()
    env.close()
    assert lost["base"] >= 6 and lost["guard"] <= lost["base"] - 4
    assert changes > 0


@pytest.mark.parametrize("prefer", ["reward", "margin"])
def test_guard_compares_every_legal_action_when_the_base_loses_one(prefer):
    env = vertiport_v1.env(config="paper")
    env.reset(seed=0)
    sim = env.unwrapped.sim
    guard = GuardController(proposer=_KeepsHolding(), horizon_min=30, nominal=True, prefer=prefer)
    col = {"reward": 1, "margin": 2}[prefer]  # the column of last_values preferred
    guard.reset(seed=0)
    guard.bind(sim)
    for _ in range(240):
        agent = env.agent_selection
        obs = env.observe(agent)
        before = sim.snapshot()
        action = guard.act(obs)
        assert obs["action_mask"][action] == 1
        after = sim.snapshot()
        for key in ("pos", "battery", "status", "node_occupant", "pending_time"):
            np.testing.assert_array_equal(before[key], after[key])  # the env is untouched
        assert before["rng"].bit_generator.state == after["rng"].bit_generator.state
        if guard.last_values:  # a full comparison: every legal action, the base's losing one
            values = guard.last_values
            assert set(values) == set(np.flatnonzero(obs["action_mask"]).tolist())
            choice = guard.proposer.act(obs)
            fewest = min(v[0] for v in values.values())
            assert values[choice][0] >= guard.settings.min_lost and values[action][0] == fewest
            if action != choice:  # of the actions that lose the fewest, the preferred one
                assert values[action][col] == max(v[col] for v in values.values()
                                                  if v[0] == fewest)
        # As a teacher: a changed decision ruled the base's choice out as unsafe.
        assert guard.last_forced == guard.last_changed == (action != guard.proposer.act(obs))
        assert guard.last_q == {}  # the base (not a planner) simulates no candidates
        env.step(action)
    assert guard.changes > 0
    guard.close()
    env.close()


def test_guard_keeps_the_base_choice_and_goes_quiet():
    env = VertiportEnv("paper")
    obs, _ = env.reset(seed=4)
    guard = GuardController(horizon_min=10, samples=1, nominal=True, quiet_pct=0.0,
                              quiet_min=5.0)
    guard.reset(seed=4)
    guard.bind(env.sim)
    base = DispatcherController()
    base.bind(env.sim)
    checked_at = []
    for _ in range(30):
        checks = guard.checks
        action = guard.act(obs)
        assert action == base.act(obs)  # nothing is lost in the first half hour
        if guard.checks > checks:
            checked_at.append(env.sim.step_count)
        obs, *_ = env.step(action)
    assert guard.changes == 0 and checked_at
    # Every check is quiet (no charge falls below 0 %): the next is at least 5 minutes later.
    assert np.all(np.diff(checked_at) >= 5)
    env.close()
    guard.close()


def test_guarded_dispatcher_loses_fewer_vehicles_than_the_dispatcher():
    """Validation day 800029 at 10 % uncertainty, its first 8 hours: the dispatcher loses
    vehicles in a queue for the one charging port; the guard keeps them."""
    env = vertiport_v1.env(config="paper_uncertain_10", **{"schedule.episode_steps": 480})
    lost = {name: run_episode(env, make_controller(name), seed=800029)["stranded"]
            for name in ("dispatcher", "guard")}
    env.close()
    assert lost["dispatcher"] >= 2
    assert lost["guard"] < lost["dispatcher"]


def test_arguments_and_unbound_use():
    with pytest.raises(RuntimeError, match="bind"):
        GuardController().act({"action_mask": np.ones(14, np.int8)})
    with pytest.raises(ValueError, match="horizon_min"):
        GuardController(horizon_min=0)
    with pytest.raises(ValueError, match="samples"):
        GuardController(samples=0)
    with pytest.raises(ValueError, match="quiet_min"):
        GuardController(quiet_min=-1)
    with pytest.raises(ValueError, match="min_lost"):
        GuardController(min_lost=0)
    with pytest.raises(ValueError, match="clairvoyant"):
        GuardController(clairvoyant=True, nominal=True)
    with pytest.raises(ValueError, match="prefer"):
        GuardController(prefer="trips")
    assert make_controller("guard").name == "guard"
    for config, runs in (("paper", 1), ("paper_uncertain", 4)):  # one where all runs are alike
        env = vertiport_v1.env(config=config)
        guard = GuardController(samples=4)
        guard.bind(env.unwrapped.sim)
        assert guard._runs == runs
        guard.close()
        env.close()
    assert make_controller("guard[samples=2]").settings.samples == 2
    assert isinstance(make_controller("guard[proposer=fcfs]").proposer, make_controller("fcfs").__class__)


@pytest.mark.parametrize("prefer, wanted", [("reward", 0), ("margin", 1)])
def test_of_the_actions_that_lose_fewest_the_guard_takes_the_preferred(prefer, wanted):
    """Where the base's choice loses a vehicle and two others lose none, ``prefer`` picks the
    one that earns more reward or the one that keeps more charge."""
    env = vertiport_v1.env(config="paper")
    sim = env.unwrapped.sim
    _, obs, legal = _dispatcher_day_to_a_choice(env, 3)
    guard = GuardController(nominal=True, prefer=prefer)
    guard.reset(seed=0)
    guard.bind(sim)
    choice = guard.proposer.act(obs)
    others = [a for a in legal if a != choice][:2]
    assert len(others) == 2
    crafted = {choice: (1.0, 90.0, 30.0), others[0]: (0.0, 50.0, 10.0),
               others[1]: (0.0, 20.0, 60.0)}
    asked = []

    def evaluate(sim, actions, stop_at_loss=False, runs=None):
        asked.append(runs)
        return {a: crafted.get(a, (2.0, 0.0, 0.0)) for a in actions}, 0.0

    guard.evaluate = evaluate
    assert guard.act(obs) == others[wanted] and guard.changes == 1
    # The check runs `samples` rollouts (the default); the comparison `compare_samples` (here
    # one: the config is nominal, so every rollout of an action is alike).
    assert asked == [None, 1]
    guard.close()
    env.close()


class _Recorder(DispatcherController):
    """The dispatcher, recording the simulator it is bound to and how often it acts."""

    def __init__(self) -> None:
        super().__init__()
        self.bound = None
        self.calls = 0

    def bind(self, sim) -> None:
        super().bind(sim)
        self.bound = sim

    def act(self, observation: dict) -> int:
        self.calls += 1
        return super().act(observation)


def test_a_fleet_of_its_own_flies_the_rollouts_and_the_base_decides_on_the_env():
    """With ``fleet`` the base is bound to the env's simulator and only decides; the fleet,
    bound to the scratch copy, flies every rollout; with a fleet that decides as the base
    does, every decision is the guard's without it."""
    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 240})
    base, fleet = _Recorder(), _Recorder()
    guard = GuardController(proposer=base, rollout_policy=fleet, horizon_min=30, nominal=True)
    plain = GuardController(proposer=_KeepsHolding(), horizon_min=30, nominal=True)
    shared = GuardController(proposer=_KeepsHolding(), rollout_policy=_KeepsHolding(), horizon_min=30,
                               nominal=True)
    env.reset(seed=0)
    guard.reset(seed=0)
    guard.bind(env.unwrapped.sim)
    assert base.bound is env.unwrapped.sim and fleet.bound is guard._scratch
    assert guard.rollout_policy is fleet and plain.rollout_policy is plain.proposer
    for seed in range(2):
        got = {}
        for name, g in (("plain", plain), ("shared", shared)):
            got[name] = (guarded_actions(env, g, seed), g.changes)
        assert got["plain"] == got["shared"] and got["plain"][1] > 0
    # The base decides once a turn; the rollouts are the fleet's.
    env.reset(seed=0)
    run_episode(env, guard, seed=0)
    assert guard.checks > 0 and fleet.calls > base.calls > 0
    assert isinstance(make_controller("guard[proposer=planner,rollout_policy=dispatcher]").own_rollout_policy,
                      DispatcherController)
    # A planner's candidate values pass through where its choice stands.
    planned = make_controller("guard[proposer=planner,rollout_policy=dispatcher,nominal=true]")
    env.reset(seed=0)
    planned.reset(seed=0)
    planned.bind(env.unwrapped.sim)
    seen = 0
    for agent in env.agent_iter(max_iter=60):
        action = planned.act(env.observe(agent))
        assert planned.last_changed or planned.last_q == planned.proposer.last_q
        seen += bool(planned.last_q)
        env.step(action)
    assert seen > 0
    planned.close()
    for g in (guard, plain, shared):
        g.close()
    env.close()


def test_defer_pct_hands_the_low_vehicles_to_the_fleet():
    """Below ``defer_pct`` the fleet decides and the base is not asked; at or above it the base
    decides; at 100 % every decision is that of the fleet guarded by itself."""
    with pytest.raises(ValueError, match="defer_pct"):
        GuardController(rollout_policy="dispatcher", defer_pct=101)
    with pytest.raises(ValueError, match="rollout_policy"):
        GuardController(defer_pct=30)
    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 240})
    sim = env.unwrapped.sim
    base = _Recorder()
    guard = GuardController(proposer=base, rollout_policy=DispatcherController(), horizon_min=30,
                              nominal=True, defer_pct=60)
    env.reset(seed=1)
    guard.reset(seed=1)
    guard.bind(sim)
    asked = {True: 0, False: 0}
    for agent in env.agent_iter():
        if env.terminations[agent] or env.truncations[agent]:
            env.step(None)
            continue
        low, calls = bool(sim.battery[sim.acting] < 60), base.calls
        action = guard.act(env.observe(agent))
        assert guard.last_deferred == low and base.calls == calls + (not low)
        asked[low] += 1
        env.step(action)
    assert asked[True] > 0 and asked[False] > 0 and guard.deferrals == asked[True]
    # Deferring every vehicle is the fleet guarded by itself, decision for decision.
    got = []
    for g in (GuardController(proposer=_KeepsHolding(), rollout_policy=DispatcherController(),
                                horizon_min=30, nominal=True, defer_pct=100),
              GuardController(proposer=DispatcherController(), horizon_min=30, nominal=True)):
        got.append(guarded_actions(env, g, seed=0))
        g.close()
    assert got[0] == got[1]
    assert make_controller("guard[rollout_policy=dispatcher,defer_pct=30]").settings.defer_pct == 30
    guard.close()
    env.close()


@pytest.mark.parametrize("margin_pct, base_stands", [(5.0, True), (25.0, False)])
def test_margin_pct_hands_an_unclean_check_to_the_fleet(margin_pct, base_stands):
    """A base choice whose rollouts keep every vehicle at 10 % stands under a 5 % margin; under
    25 % the fleet's own choice is checked and taken."""
    env = vertiport_v1.env(config="paper")
    sim = env.unwrapped.sim
    fleet, obs, legal = _dispatcher_day_to_a_choice(env, 2)
    own = fleet.act(obs)
    other = next(a for a in legal if a != own)
    guard = GuardController(proposer=FixedAction(other), rollout_policy=fleet, nominal=True,
                              margin_pct=margin_pct)
    guard.reset(seed=0)
    guard.bind(sim)
    least = {other: 10.0, own: 40.0}
    checked = []

    def crafted(sim, actions, stop_at_loss=False, runs=None):
        checked.extend(actions)
        return {a: (0.0, 0.0, least[a]) for a in actions}, min(least[a] for a in actions)

    guard.evaluate = crafted
    assert guard.act(obs) == (other if base_stands else own)
    assert guard.last_deferred is (not base_stands) and guard.deferrals == (not base_stands)
    assert checked == ([other] if base_stands else [other, own])
    # Quiet minutes only after a check that keeps every vehicle at quiet_pct (20) and margin_pct.
    assert (guard._quiet_until_step > 0) is (not base_stands)
    if not base_stands:  # the fleet's choice keeps 22 %: clean, but not quiet under a 25 % margin
        least[own] = 22.0
        guard.reset(seed=0)
        assert guard.act(obs) == own and guard._quiet_until_step == -1
    with pytest.raises(ValueError, match="margin_pct"):
        GuardController(margin_pct=10)
    guard.close()
    env.close()


def test_self_check_hands_a_choice_the_base_itself_would_lose_to_the_fleet():
    """A base choice that passes the fleet's rollouts stands only if the rollouts in which the
    base goes on deciding lose nothing either; otherwise the fleet's choice is checked and
    taken."""
    env = vertiport_v1.env(config="paper")
    sim = env.unwrapped.sim
    fleet, obs, legal = _dispatcher_day_to_a_choice(env, 2)
    own = fleet.act(obs)
    other = next(a for a in legal if a != own)
    for onward_loses in (False, True):
        guard = GuardController(proposer=FixedAction(other), rollout_policy=fleet, nominal=True,
                                  self_check=True)
        guard.reset(seed=0)
        guard.bind(sim)
        checked = []

        def crafted(sim, actions, stop_at_loss=False, policy=None, runs=None):
            onward = policy is guard.onward
            checked.append((actions[0], onward))
            lost = 1.0 if onward and onward_loses else 0.0
            return {a: (lost, 0.0, 50.0) for a in actions}, 50.0

        guard.evaluate = crafted
        assert guard.act(obs) == (own if onward_loses else other)
        assert guard.last_deferred is onward_loses and guard.deferrals == onward_loses
        assert checked == ([(other, False), (other, True), (own, False)] if onward_loses
                           else [(other, False), (other, True)])
        guard.close()
    with pytest.raises(ValueError, match="rollout_policy"):
        GuardController(self_check=True)
    with pytest.raises(ValueError, match="scratch copy"):
        GuardController(proposer="planner", rollout_policy="dispatcher", self_check=True)
    env.close()


def test_the_self_checks_continuation_is_the_base_above_defer_pct_and_the_fleet_below():
    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 120})
    base, fleet = FixedAction(0), DispatcherController()
    guard = GuardController(proposer=base, rollout_policy=fleet, nominal=True, defer_pct=50,
                              self_check=True)
    env.reset(seed=0)
    guard.bind(env.unwrapped.sim)
    onward, scratch = guard.onward, guard._scratch
    assert onward.sim is scratch and onward.policy is base and not onward.pure_act
    scratch.restore(env.unwrapped.sim.snapshot())
    obs = ObservationBuilder(scratch).observe(scratch.acting)
    v = scratch.acting
    for pct, wanted in ((80.0, 0), (20.0, fleet.act(obs))):
        scratch.battery[v] = pct
        assert onward.act(obs) == wanted
    guard.close()
    env.close()


def test_self_check_keeps_the_vehicles_a_holding_base_loses():
    """A base that keeps its vehicles hovering passes the dispatcher's rollouts (the dispatcher
    lands them at their next turn); its own rollouts lose them, and the fleet decides."""
    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 240})
    lost, deferrals = {}, {}
    for self_check in (False, True):
        lost[self_check] = deferrals[self_check] = 0
        for seed in range(2):
            guard = GuardController(proposer=_KeepsHolding(), rollout_policy=DispatcherController(),
                                      horizon_min=30, nominal=True, self_check=self_check)
            lost[self_check] += run_episode(env, guard, seed=seed)["stranded"]
            deferrals[self_check] += guard.deferrals
            guard.close()
    env.close()
    assert deferrals[False] == 0 and deferrals[True] > 0
    assert lost[True] < lost[False]
