"""Fitting the actor with the dispatcher as its prior (``pretrain.rule_weight``): the days keep
the dispatcher's choice, the actor drives and proposes as the prior, the fit weighs the rule's
choice as the prior does in play, and a checkpoint fit so tells ``prior`` its weight."""

import copy

import numpy as np
import pytest
import torch
from helpers import small_actor

from agents.controllers.gcn import GCNController, read_checkpoint
from agents.controllers.prior import DEFAULT_WEIGHT, RulePriorController
from agents.gcn.padding import to_padded_action
from agents.training import demonstrations
from agents.training.config import TrainConfig, load_train_config
from agents.training.demonstrations import DayTask, label_day, pad_day, round_tasks
from agents.training.imitation import fit_actor
from agents.training.teachers import make_teacher
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict

SHIPPED = "agents/checkpoints/gcn_default.pt"


def test_a_prior_day_keeps_the_rules_choice_and_drives_as_the_prior():
    env_cfg = to_dict(load_config("paper"))
    learner = read_checkpoint(SHIPPED)
    data, metrics = label_day(DayTask(env_cfg, 3, 200, "dispatcher", 4, learner=learner,
                                      rule_weight=60.0))
    assert data["rule"].shape == data["label"].shape and len(data["rule"]) > 20
    assert data["action_mask"][np.arange(len(data["rule"])), data["rule"]].all()
    np.testing.assert_array_equal(data["label"], data["rule"])  # the dispatcher labels
    # At a weight of 60 the prior plays the dispatcher: the day is the dispatcher's own, which
    # the policy alone does not play.
    _, own = label_day(DayTask(env_cfg, 3, 200, "dispatcher", 4))
    alone, by_policy = label_day(DayTask(env_cfg, 3, 200, "dispatcher", 4, learner=learner))
    assert metrics == own and by_policy != own
    assert "rule" not in alone
    padded = pad_day(data, 14, 6)
    np.testing.assert_array_equal(padded["rule"], to_padded_action(data["rule"], 10, 14))


def test_the_fit_weighs_the_rules_choice_as_the_prior_plays():
    env_cfg = to_dict(load_config("paper"))
    data, _ = label_day(DayTask(env_cfg, 5, 120, "dispatcher", 4,
                                learner=read_checkpoint(SHIPPED), rule_weight=1.0))
    torch.manual_seed(0)
    actor = small_actor()
    quiet = dict(log=lambda *_: None, tag="t")
    alone = fit_actor(copy.deepcopy(actor), data, 1, 64, 1e-9, 0, **quiet)
    prior = fit_actor(copy.deepcopy(actor), data, 1, 64, 1e-9, 0, rule_weight=8.0, **quiet)
    # The labels are the rule's choices: with the prior they are nearly certain already.
    assert prior["cross_entropy"] < 0.1 < alone["cross_entropy"]
    assert prior["accuracy"] == 1.0 > alone["accuracy"]
    with pytest.raises(ValueError, match="rule's choice"):
        fit_actor(actor, {k: v for k, v in data.items() if k != "rule"}, 1, 64, 1e-3, 0,
                  rule_weight=1.0, **quiet)


def test_the_teacher_and_the_rounds_get_the_weight():
    learner = read_checkpoint(SHIPPED)
    teacher = make_teacher("lookahead", 40, 3.0, seed=3, learner=learner, rule_weight=2.0)
    assert isinstance(teacher.look.proposer, RulePriorController)
    assert teacher.look.proposer.weight == 2.0
    assert isinstance(make_teacher("lookahead", 40, 3.0, 3, learner=learner).look.proposer,
                      GCNController)
    cfg = load_train_config("expert_iteration_prior")
    assert cfg.pretrain.rule_weight == 2.0 and cfg.pretrain.teacher == "lookahead"
    tasks = round_tasks(cfg, to_dict(load_config("paper")), 1, learner, last=False)
    assert {t.rule_weight for t in tasks} == {2.0}


def test_the_actor_may_propose_to_the_teacher_alone(monkeypatch):
    learner = read_checkpoint(SHIPPED)
    base = to_dict(load_train_config("expert_iteration_prior"))
    cfg = build_dataclass(TrainConfig, {**base, "pretrain": {**base["pretrain"],
                                                             "propose_with_prior": False}})
    tasks = round_tasks(cfg, to_dict(load_config("paper")), 1, learner, last=False)
    assert {(t.rule_weight, t.propose_with_prior) for t in tasks} == {(2.0, False)}
    seen = []
    real = demonstrations.make_teacher
    monkeypatch.setattr(demonstrations, "make_teacher",
                        lambda *a, **k: seen.append(k["rule_weight"]) or real(*a, **k))
    env_cfg = to_dict(load_config("paper"))
    for alone in (False, True):
        data, _ = label_day(DayTask(env_cfg, 3, 40, "dispatcher", 4, learner=learner,
                                    rule_weight=2.0, propose_with_prior=not alone))
        assert "rule" in data  # the actor still drives and is fit with its prior
    assert seen == [2.0, 0.0]


def test_a_checkpoint_fit_with_the_prior_tells_prior_its_weight():
    content = read_checkpoint(SHIPPED)
    assert RulePriorController(policy=GCNController(content)).weight == DEFAULT_WEIGHT
    fit = copy.deepcopy(content)
    fit["infos"]["marl_vertiport"]["train_config"]["pretrain"]["rule_weight"] = 2.0
    assert RulePriorController(policy=GCNController(fit)).weight == 2.0
    assert RulePriorController(policy=GCNController(fit), weight=0.5).weight == 0.5


@pytest.mark.parametrize("change, match", [
    ({"pretrain": {"rule_weight": -1.0}}, "finite number of nats"),
    ({"pretrain": {"rule_weight": float("nan")}}, "rule_weight: must be a finite number"),
    ({"pretrain": {"days": 0}}, "needs pretrain.days"),
    ({"init_checkpoint": "", "ensemble": {"fits": 2}}, "needs pretrain.days .* ensemble.fits: 0"),
    ({"iterations": 3}, "PPO does not train an actor"),
    ({"pretrain": {"rule_weight": 0.0, "propose_with_prior": False}}, "propose_with_prior: false"),
    ({"pretrain": {"teacher": "dispatcher", "propose_with_prior": False}}, "teacher: lookahead"),
])
def test_a_rule_weight_the_run_cannot_honour_is_refused(change, match):
    base = to_dict(load_train_config("expert_iteration_prior"))
    data = {k: ({**base[k], **v} if isinstance(v, dict) else v) for k, v in change.items()}
    with pytest.raises(ConfigError, match=match):
        build_dataclass(TrainConfig, {**base, **data})
