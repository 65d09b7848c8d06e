"""What an override of the guard may pick: ``min_saved`` leaves the base's choice standing
unless another action loses that many vehicles fewer, ``override_takeoff=False`` keeps the
guard from starting a trip the base did not choose, and ``port_hops=False`` from taxiing a
vehicle between normal ports (the base's own hop is handed over too)."""

import numpy as np
import pytest

from agents.controllers.dispatcher import DispatcherController
from agents.controllers.guard import GuardController
from agents.controllers.registry import make_controller
from helpers import FixedAction, dispatcher_decision
from marl_vertiport import vertiport_v1
from marl_vertiport.sim.schema import ON_CHARGER, ON_PORT


def _decision_with_a_takeoff(env):
    """Day 0 of ``env`` flown by the dispatcher up to a decision, on a port or a charger, whose
    legal actions include a take-off the dispatcher does not choose and two other actions:
    (that decision's observation, the dispatcher's choice, its legal actions)."""
    _, obs, choice, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        sim.status[sim.acting] in (ON_PORT, ON_CHARGER) and sim.actions.takeoff in legal
        and choice != sim.actions.takeoff and len(legal) >= 3))
    return obs, choice, legal


def _crafted(guard, values):
    """Make ``guard``'s rollouts return ``values`` (per action: mean lost, reward, least charge;
    an action not named loses two vehicles); returns the list of the actions each call asked."""
    asked = []

    def evaluate(sim, actions, stop_at_loss=False, runs=None):
        asked.append(list(actions))
        return {a: values.get(a, (2.0, 0.0, 0.0)) for a in actions}, 0.0

    guard.evaluate = evaluate
    return asked


def test_the_override_arguments_are_validated_and_parsed():
    with pytest.raises(ValueError, match="min_saved"):
        GuardController(min_saved=-0.25)
    guard = make_controller("lookahead[min_saved=0.5,override_takeoff=false,port_hops=false]")
    assert guard.settings.min_saved == 0.5 and guard.settings.override_takeoff is False
    assert guard.settings.port_hops is False
    guard.close()
    default = GuardController()
    assert default.settings.min_saved == 0.0 and default.settings.override_takeoff is True
    assert default.settings.port_hops is True
    default.close()


@pytest.mark.parametrize("min_saved, changed", [(0.0, True), (0.5, True), (0.75, False)])
def test_min_saved_is_the_least_gain_an_override_needs(min_saved, changed):
    """The base's choice loses 0.75 vehicles on average, another action 0.25: a gain of 0.5,
    enough for an override up to ``min_saved=0.5`` and not above."""
    env = vertiport_v1.env(config="paper")
    obs, choice, legal = _decision_with_a_takeoff(env)
    guard = GuardController(nominal=True, min_saved=min_saved)
    guard.reset(seed=0)
    guard.bind(env.unwrapped.sim)
    other = next(a for a in legal if a != choice)
    _crafted(guard, {choice: (0.75, 50.0, 20.0), other: (0.25, 10.0, 20.0)})
    assert guard.act(obs) == (other if changed else choice)
    assert guard.changes == int(changed) and guard.last_changed == changed
    guard.close()
    env.close()


@pytest.mark.parametrize("override_takeoff", [True, False])
def test_without_override_takeoff_the_guard_starts_no_trip_the_base_did_not_choose(
        override_takeoff):
    """The base's choice loses a vehicle; the take-off loses none and another action loses
    fewer than the choice. With ``override_takeoff`` the guard takes off; without, the take-off
    is not even rolled out and the other action is taken."""
    env = vertiport_v1.env(config="paper")
    obs, choice, legal = _decision_with_a_takeoff(env)
    sim = env.unwrapped.sim
    takeoff = sim.actions.takeoff
    guard = GuardController(nominal=True, override_takeoff=override_takeoff)
    guard.reset(seed=0)
    guard.bind(sim)
    other = next(a for a in legal if a not in (choice, takeoff))
    asked = _crafted(guard, {choice: (1.0, 50.0, 20.0), takeoff: (0.0, 90.0, 50.0),
                             other: (0.5, 10.0, 20.0)})
    assert guard.act(obs) == (takeoff if override_takeoff else other)
    assert asked[0] == [choice]  # the check
    assert (takeoff in asked[1]) == override_takeoff and choice in asked[1]
    assert set(asked[1]) | {takeoff} == set(legal)
    guard.close()
    env.close()


def test_without_override_takeoff_the_base_may_still_take_off():
    """A take-off the base chose is compared as usual and stands where nothing loses fewer."""
    env = vertiport_v1.env(config="paper")
    obs, _, legal = _decision_with_a_takeoff(env)
    sim = env.unwrapped.sim
    takeoff = sim.actions.takeoff
    guard = GuardController(proposer=FixedAction(takeoff), nominal=True, override_takeoff=False)
    guard.reset(seed=0)
    guard.bind(sim)
    asked = _crafted(guard, {a: (1.0, 0.0, 20.0) for a in legal})
    assert guard.act(obs) == takeoff and guard.changes == 0
    assert takeoff in asked[1]
    guard.close()
    env.close()


def _decision_with_a_hop(env):
    """The first day of ``env``, flown by the dispatcher, with a decision of a vehicle on a
    normal port that may taxi to the other normal port (rare: the dispatcher seldom lands on
    one), played up to it: (its observation, the dispatcher's choice, the hop)."""
    def hop(sim, legal):
        return next((a for a in map(sim.actions.node_action, range(sim.layout.n_normal))
                     if a in legal), None)

    _, obs, choice, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        sim.status[sim.acting] == ON_PORT and hop(sim, legal) is not None), seeds=range(20))
    return obs, choice, hop(env.unwrapped.sim, legal)


class _Hops(DispatcherController):
    """The dispatcher, except that a vehicle on a normal port taxis to another if it may."""

    def act(self, observation):
        mask = observation["action_mask"]
        for a in self.hop_actions:
            if mask[a]:
                return a
        return super().act(observation)


@pytest.mark.parametrize("fleet", [None, "dispatcher"])
def test_without_port_hops_a_taxi_between_normal_ports_is_handed_over(fleet):
    """A base that hops: with ``port_hops`` its hop stands where the check is clean; without,
    ``fleet`` decides (``stay`` without a fleet), and the choice is never a hop."""
    env = vertiport_v1.env(config="paper")
    obs, dispatcher_choice, hop = _decision_with_a_hop(env)
    sim = env.unwrapped.sim
    base = _Hops()
    base.hop_actions = [sim.actions.node_action(k) for k in range(sim.layout.n_normal)]
    assert dispatcher_choice not in base.hop_actions and obs["action_mask"][sim.actions.stay]
    wanted = dispatcher_choice if fleet else sim.actions.stay
    for port_hops in (True, False):
        guard = GuardController(proposer=base, nominal=True, rollout_policy=fleet, port_hops=port_hops)
        guard.reset(seed=0)
        guard.bind(sim)
        _crafted(guard, {a: (0.0, 0.0, 50.0) for a in range(sim.actions.n)})
        assert guard.act(obs) == (hop if port_hops else wanted)
        assert guard.deferrals == int(not port_hops and fleet is not None)
        guard.close()
    env.close()


def test_without_port_hops_no_override_taxis_between_normal_ports():
    """The base's choice loses a vehicle, the hop loses none and another action fewer than the
    choice: without ``port_hops`` the other action is taken and the hop is not rolled out."""
    env = vertiport_v1.env(config="paper")
    obs, choice, hop = _decision_with_a_hop(env)
    sim = env.unwrapped.sim
    legal = np.flatnonzero(obs["action_mask"]).tolist()
    other = next(a for a in legal if a not in (choice, hop))
    for port_hops, picked in ((True, hop), (False, other)):
        guard = GuardController(nominal=True, port_hops=port_hops)
        guard.reset(seed=0)
        guard.bind(sim)
        asked = _crafted(guard, {choice: (1.0, 50.0, 20.0), hop: (0.0, 90.0, 50.0),
                                 other: (0.0, 10.0, 20.0)})
        assert guard.act(obs) == picked
        assert (hop in asked[1]) == port_hops
        guard.close()
    env.close()


@pytest.mark.parametrize("fleet_values, reward_margin, fleet_taken", [
    ((0.0, 60.0, 30.0), 0.0, True),    # loses none, earns more
    ((0.0, 60.0, 30.0), 20.0, False),  # but not by the margin
    ((0.0, 40.0, 30.0), 0.0, False),   # earns less
    ((0.5, 90.0, 30.0), 0.0, False),   # earns more, but loses a vehicle
])
def test_reward_margin_takes_the_fleets_choice_where_its_rollouts_earn_more(
        fleet_values, reward_margin, fleet_taken):
    """A base that takes off where the dispatcher (the fleet) does not: its take-off passes the
    check, earning 50; the dispatcher's choice is rolled out after it and taken only where it
    loses no vehicle and earns ``reward_margin`` more."""
    env = vertiport_v1.env(config="paper")
    obs, choice, _ = _decision_with_a_takeoff(env)
    sim = env.unwrapped.sim
    takeoff = sim.actions.takeoff
    guard = GuardController(proposer=FixedAction(takeoff), rollout_policy="dispatcher", nominal=True,
                              reward_margin=reward_margin)
    guard.reset(seed=0)
    guard.bind(sim)
    asked = _crafted(guard, {takeoff: (0.0, 50.0, 30.0), choice: fleet_values})
    assert guard.act(obs) == (choice if fleet_taken else takeoff)
    assert asked == [[takeoff], [choice]]
    assert guard.contests_won == guard.deferrals == int(fleet_taken)
    assert guard.last_deferred == fleet_taken and guard.changes == 0
    guard.close()
    env.close()


def test_reward_margin_rolls_out_nothing_more_where_the_two_agree_and_needs_a_fleet():
    with pytest.raises(ValueError, match="reward_margin .* needs a rollout_policy"):
        GuardController(reward_margin=0.0)
    assert make_controller("lookahead[reward_margin=5]").settings.reward_margin == 5.0
    env = vertiport_v1.env(config="paper")
    obs, choice, _ = _decision_with_a_takeoff(env)
    guard = GuardController(rollout_policy="dispatcher", nominal=True, reward_margin=0.0)
    guard.reset(seed=0)
    guard.bind(env.unwrapped.sim)
    asked = _crafted(guard, {choice: (0.0, 50.0, 30.0)})
    assert guard.act(obs) == choice and asked == [[choice]] and guard.contests_won == 0
    guard.close()
    env.close()
