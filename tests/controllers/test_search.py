"""The wide look-ahead search (``candidates=k``): which candidates it rolls out, that it takes
the one that loses the fewest and earns the most with the same draws for all, and that the
rollout policy's choice keeps ties."""

import numpy as np
import pytest
from helpers import FixedAction, dispatcher_decision

from agents.controllers.guard import GuardController
from agents.controllers.lookahead_settings import LookaheadSettings
from agents.controllers.registry import make_controller
from agents.controllers.search import LOSS_COST, candidate_actions, confident_choice
from marl_vertiport import vertiport_v1
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT


class _Prefers:
    """A proposer with fixed probabilities over the actions."""

    def __init__(self, p):
        self.p = np.asarray(p, dtype=float)

    def action_probabilities(self, observation):
        return self.p * observation["action_mask"]

    def act(self, observation):
        return int(np.argmax(self.action_probabilities(observation)))


def test_candidates_are_the_rollout_policys_choice_then_the_proposers_most_probable():
    obs = {"action_mask": np.array([1, 1, 0, 1, 1], dtype=np.int8)}
    legal = [0, 1, 3, 4]
    proposer = _Prefers([0.1, 0.2, 0.0, 0.5, 0.2])
    assert candidate_actions(proposer, obs, legal, 1, also=0) == [0, 3]
    assert candidate_actions(proposer, obs, legal, 2, also=0) == [0, 3, 1]  # tie: lower index
    assert candidate_actions(proposer, obs, legal, 2, also=3) == [3, 1, 4]
    assert candidate_actions(proposer, obs, legal, 99, also=4) == [4, 3, 1, 0]
    # A proposer without probabilities offers every legal action.
    assert candidate_actions(FixedAction(1), obs, legal, 1, also=4) == [4, 0, 1, 3]


def test_the_setting_is_checked():
    with pytest.raises(ValueError, match="candidates"):
        LookaheadSettings(candidates=-1)
    with pytest.raises(ValueError, match="confidence must be >= 0 standard errors, got -1"):
        LookaheadSettings(confidence=-1)
    assert make_controller("lookahead[candidates=3]").settings.candidates == 3


def test_a_confident_search_leaves_the_base_only_for_a_gain_clear_of_its_noise():
    """The paired gain's lower bound (mean less z standard errors) decides: a lucky loss-free
    sample, or a larger but noisier mean, does not move the search off the base."""
    base = [(0.0, 10.0), (0.0, 12.0), (0.0, 11.0), (0.0, 9.0)]
    steady = [(0.0, 13.0), (0.0, 15.0), (0.0, 14.0), (0.0, 12.0)]  # +3 on every draw
    noisy = [(0.0, 40.0), (0.0, 2.0), (0.0, 50.0), (0.0, 0.0)]  # +12.5 on average, se 12.3
    runs = {0: base, 1: steady, 2: noisy}
    assert confident_choice(runs, 0, [0, 1, 2], 2.0, 0.0) == 1
    assert confident_choice(runs, 0, [0, 2], 2.0, 0.0) == 0
    assert confident_choice(runs, 0, [0, 2], 0.5, 0.0) == 2  # a weaker bound lets it through
    assert confident_choice(runs, 0, [0, 1], 2.0, 3.5) == 0  # the margin is on top of the bound
    # The base loses a vehicle on one draw of four: a quarter of LOSS_COST on average, but no
    # clear gain for a candidate that earns less on the other three.
    lossy = [(1.0, 10.0), (0.0, 12.0), (0.0, 11.0), (0.0, 9.0)]
    safe = [(0.0, 5.0), (0.0, 7.0), (0.0, 6.0), (0.0, 4.0)]
    assert confident_choice({0: lossy, 1: safe}, 0, [0, 1], 2.0, 0.0) == 0
    assert confident_choice({0: lossy, 1: safe}, 0, [0, 1], 0.0, 0.0) == 1  # the means: LOSS_COST
    assert LOSS_COST / 4 > 5
    # One rollout an action (no uncertainty): the standard error is 0, the means decide.
    assert confident_choice({0: [(0.0, 1.0)], 1: [(0.0, 2.0)]}, 0, [0, 1], 3.0, 0.0) == 1


def test_the_search_records_every_rollout_of_every_candidate():
    env = vertiport_v1.env(config="paper_uncertain", **{"schedule.episode_steps": 60})
    _, obs, _, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        len(legal) >= 2 and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)))
    search = make_controller("lookahead[candidates=99,horizon_min=20,samples=3,confidence=2]")
    search.reset(seed=0)
    search.bind(env.unwrapped.sim)
    action = search.act(obs)
    runs, values = search.last_runs, search.last_values
    assert set(runs) == set(values) == set(legal) and action in runs
    for a, rollouts in runs.items():
        assert len(rollouts) == 3
        assert values[a][:2] == pytest.approx(tuple(np.mean(rollouts, axis=0)))
    base = search.rollout_policy.act(obs)
    assert action == confident_choice(runs, base, list(runs), 2.0, 0.0)
    search.close()
    env.close()


def test_the_wide_search_takes_the_best_candidate_by_its_rollouts():
    """At decisions with a choice, the action taken is, among the candidates it rolled out,
    one that loses the fewest vehicles and, of those, earns the most; the dispatcher's choice
    is always a candidate and keeps a tie."""
    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 200})
    search = GuardController(proposer="dispatcher", rollout_policy="dispatcher", nominal=True,
                             horizon_min=30, quiet_pct=101.0, candidates=99)
    env.reset(seed=3)
    search.reset(seed=3)
    search.bind(env.unwrapped.sim)
    sim = env.unwrapped.sim
    dispatcher = make_controller("dispatcher")
    dispatcher.bind(sim)
    checked = changed = 0
    for agent in env.agent_iter():
        if env.terminations[agent] or env.truncations[agent]:
            env.step(None)
            continue
        obs = env.observe(agent)
        legal = np.flatnonzero(obs["action_mask"]).tolist()
        status = sim.status[sim.acting]
        base = dispatcher.act(obs)
        action = search.act(obs)
        if len(legal) > 1 and status in (ON_PORT, ON_CHARGER, HOVERING):
            values = search.last_values
            assert set(values) == set(legal) and base in values  # every legal action, here
            fewest = min(v[0] for v in values.values())
            best_reward = max(v[1] for v in values.values() if v[0] <= fewest)
            assert values[action][0] == fewest and values[action][1] == best_reward
            if values[base][0] <= fewest and values[base][1] == best_reward:
                assert action == base
            checked += 1
            changed += action != base
        env.step(action)
    assert checked > 20 and changed > 0  # it looked, and it found something better
    search.close()
    env.close()


def test_the_wide_search_decides_the_same_from_the_same_state():
    env = vertiport_v1.env(config="paper_uncertain", **{"schedule.episode_steps": 60})
    _, obs, _, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        len(legal) >= 3 and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)))
    sim = env.unwrapped.sim
    picks = []
    for _ in range(2):
        search = make_controller("lookahead[candidates=2,horizon_min=20,samples=2]")
        search.reset(seed=0)
        search.bind(sim)
        picks.append((search.act(obs), dict(search.last_values)))
        search.close()
    assert picks[0] == picks[1] and len(picks[0][1]) >= 2
    env.close()


def test_the_search_teacher_labels_with_its_candidates_values():
    """As a teacher (pretrain.teacher: search) the wide search gives its label and the value of
    every legal action it rolled out, a vehicle lost worth LOSS_COST of reward, and calls a
    decision forced where one candidate loses a vehicle that another keeps."""
    from agents.controllers.search import LOSS_COST
    from agents.training.teachers import make_teacher

    teacher = make_teacher("search", 40, 3.0, seed=5)
    assert teacher.settings.candidates >= 99 and teacher.settings.samples == 4
    env = vertiport_v1.env(config="paper_uncertain", **{"schedule.episode_steps": 60})
    _, obs, _, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        len(legal) >= 2 and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)))
    teacher.reset(seed=0)
    teacher.bind(env.unwrapped.sim)
    label = teacher.act(obs)
    q = teacher.last_q
    assert set(q) == set(legal) and label in q
    assert q == {a: v[1] - LOSS_COST * v[0] for a, v in teacher.last_values.items()}
    lost = [v[0] for v in teacher.last_values.values()]
    assert teacher.last_forced == (max(lost) > min(lost))
    teacher.close()
    env.close()


def test_the_leaf_value_adds_the_end_states_held_terms_to_each_rollout():
    """With ``leaf_turns`` each rollout's reward gains the planner's terminal value of the state
    it ends in; the vehicles lost do not change."""
    from agents.controllers.planner import held_terms_value

    env = vertiport_v1.env(config="paper", **{"schedule.episode_steps": 80})
    _, obs, _, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        len(legal) >= 2 and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)))
    sim = env.unwrapped.sim
    values = {}
    for turns in (0.0, 6.0):
        search = GuardController(proposer="dispatcher", rollout_policy="dispatcher",
                                 nominal=True, horizon_min=20, leaf_turns=turns)
        search.reset(seed=0)
        search.bind(sim)
        values[turns], _ = search.evaluate(sim, [legal[0]])
        end = search._scratch  # the end state of the one rollout
        leaf = held_terms_value(end, turns)
        search.close()
    assert leaf != 0.0
    assert values[6.0][legal[0]][0] == values[0.0][legal[0]][0]
    assert values[6.0][legal[0]][1] == pytest.approx(values[0.0][legal[0]][1] + leaf)
    with pytest.raises(ValueError, match="leaf_turns must be >= 0 turns, got -2"):
        LookaheadSettings(leaf_turns=-2)
    env.close()
