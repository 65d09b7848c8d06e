"""`prior`: a policy with a rule as its prior. The rule's choice stands unless the policy holds
another action more than e^weight times likelier; weight 0 is the policy, a large weight the
rule; bad arguments are refused with what is wrong; results record the checkpoint it plays."""

import math
from pathlib import Path

import numpy as np
import pytest

from agents.common.specs import checkpoint_files
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.episode import run_episode
from agents.controllers.gcn import GCNController
from agents.controllers.prior import DEFAULT_WEIGHT, RulePriorController
from agents.controllers.registry import SHIPPED_CHECKPOINT, make_controller
from marl_vertiport import vertiport_v1


class _Fixed:
    """A policy with fixed probabilities, or a rule with a fixed choice."""

    def __init__(self, probs=None, choice=0):
        self.probs, self.choice = probs, choice

    def action_probabilities(self, observation):
        return np.asarray(self.probs)

    def act(self, observation):
        return self.choice


def _obs(mask):
    return {"action_mask": np.asarray(mask, dtype=np.int8)}


def test_the_rule_stands_unless_the_policy_is_e_to_the_weight_surer():
    probs = [0.0, 0.6, 0.3, 0.1]
    obs = _obs([0, 1, 1, 1])
    # The policy holds action 1 twice as likely as the rule's action 2: the threshold is ln 2.
    for weight, expected in [(0.99 * math.log(2), 1), (1.01 * math.log(2), 2)]:
        prior = RulePriorController(policy=_Fixed(probs), rule=_Fixed(choice=2), weight=weight)
        assert prior.act(obs) == expected
    prior = RulePriorController(policy=_Fixed(probs), rule=_Fixed(choice=3), weight=0.0)
    assert prior.act(obs) == 1 and prior.departures == 1 and prior.decisions == 1
    scores = prior.scores(obs)
    assert scores[0] == -np.inf and scores[3] == pytest.approx(math.log(0.1))
    p = RulePriorController(policy=_Fixed(probs), rule=_Fixed(choice=3),
                            weight=math.log(3.0)).action_probabilities(obs)
    assert p.sum() == pytest.approx(1.0) and p[0] == 0.0
    assert p[3] == pytest.approx(0.3 / 1.2) and p[1] == pytest.approx(0.6 / 1.2)


def test_an_illegal_rule_choice_gets_no_weight_and_a_zero_probability_stays_legal():
    prior = RulePriorController(policy=_Fixed([0.0, 0.0, 1.0]), rule=_Fixed(choice=0), weight=5)
    assert prior.act(_obs([0, 1, 1])) == 2  # the rule's choice is masked: the policy's stands
    prior = RulePriorController(policy=_Fixed([0.0, 0.0, 1.0]), rule=_Fixed(choice=1), weight=5)
    assert prior.act(_obs([0, 1, 1])) == 2  # a zero-probability action gets the bonus, not -inf
    assert np.isfinite(prior.scores(_obs([0, 1, 1]))[1])


def _actions(env, controller, seed, probes):
    """``controller`` drives a day; at each decision with a choice, what every probe picks."""
    picks = {name: [] for name in probes}

    def before(agent, obs, env):
        if obs["action_mask"].sum() > 1:
            for name, probe in probes.items():
                picks[name].append(int(probe.act(obs)))
    for probe in probes.values():
        probe.reset(seed=seed)
        if hasattr(probe, "bind"):
            probe.bind(env.unwrapped.sim)
    run_episode(env, controller, seed, before_step=before)
    return picks


@pytest.mark.parametrize("config", ["paper", "paper_uncertain_10"])
def test_weight_zero_is_the_policy_and_a_large_weight_is_the_rule(config):
    env = vertiport_v1.env(config=config, **{"schedule.episode_steps": 120})
    prior = make_controller("prior")
    assert isinstance(prior, RulePriorController) and prior.weight == DEFAULT_WEIGHT
    assert isinstance(prior.policy, GCNController) and prior.policy.path == SHIPPED_CHECKPOINT
    assert isinstance(prior.rule, DispatcherController)
    probes = {"zero": make_controller("prior[weight=0]"),
              "huge": make_controller("prior[weight=60]"),
              "gcn": make_controller("gcn"), "dispatcher": DispatcherController()}
    picks = _actions(env, prior, seed=7, probes=probes)
    assert len(picks["gcn"]) > 50
    assert picks["zero"] == picks["gcn"] and picks["huge"] == picks["dispatcher"]
    assert picks["gcn"] != picks["dispatcher"]  # the test can tell the two apart
    # The prior took the rule's choice where the two agree, and departs only from the rule.
    assert 0 < prior.departures < prior.decisions == len(picks["gcn"])
    env.close()


def test_bad_arguments_name_what_is_wrong():
    for spec, match in [("prior[weight=-1]", "weight must be a finite number"),
                        ("prior[weight=.inf]", "weight must be a finite number"),
                        ("prior[weight=abc]", "weight must be a number"),
                        ("prior[weight=true]", "weight must be a number"),
                        ("prior[policy=dispatcher]", "gives no action probabilities"),
                        ("prior[rule=nope]", "unknown agent 'nope'")]:
        with pytest.raises(Exception, match=match):
            make_controller(spec)
    with pytest.raises(ValueError, match="has no act"):
        RulePriorController(rule=object())


def test_a_prior_proposes_inside_the_look_ahead():
    look = make_controller("lookahead[proposer=prior[weight=1]]")
    assert isinstance(look.proposer, RulePriorController) and look.proposer.weight == 1.0


def test_results_record_the_checkpoint_a_prior_plays():
    assert checkpoint_files("prior") == [SHIPPED_CHECKPOINT]
    assert checkpoint_files("prior[policy=runs/x/model_3.pt,weight=1]") == [
        Path("runs/x/model_3.pt")]
    assert checkpoint_files("lookahead[proposer=prior[policy=a.pt]]") == [
        Path("a.pt")]
    assert checkpoint_files("prior[policy=gcn,rule=fcfs]") == [SHIPPED_CHECKPOINT]
