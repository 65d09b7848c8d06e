"""The ensemble stage (agents/training/ensemble.py): refits of the warm start's
demonstrations, days driven by their ensemble, and the actor distilled from it."""

import numpy as np
import pytest
import torch

from agents.controllers.gcn import GCNController
from agents.training.config import TrainConfig
from agents.training.pipeline import train
from marl_vertiport.config import ConfigError, build_dataclass, to_dict

PRETRAIN = {"days": 1, "day_steps": 40, "starts": 1, "start_steps": 12, "low_battery_starts": 0,
            "teacher": "dispatcher", "workers": 1, "epochs": 2, "batch_size": 32,
            "learning_rate": 1e-3}


def config(**extra) -> TrainConfig:
    base = to_dict(TrainConfig())
    base.update(mode="multi_agent", num_envs=2, num_steps_per_env=8, iterations=1,
                save_interval=1, critic_warmup_iterations=1, pretrain=PRETRAIN,
                evaluation={"episodes": 0, "agents": []})
    base.update(extra)
    return build_dataclass(TrainConfig, base)


def actor_weights(path):
    return torch.load(path, weights_only=True)["actor_state_dict"]


def test_the_ensemble_stage_distils_into_the_actor_ppo_starts_from(tmp_path):
    lines = []
    cfg = config(ensemble={"fits": 2, "days": 1, "epochs": 2})
    train(cfg, tmp_path / "a", log=lines.append, evaluate=False)
    run = tmp_path / "a"
    warm, distilled = actor_weights(run / "model_warmstart.pt"), actor_weights(run / "model_distilled.pt")
    first = actor_weights(run / "model_0.pt")  # the critic warm-up: the actor frozen
    assert all(torch.equal(first[k], distilled[k]) for k in distilled)
    assert not all(torch.equal(warm[k], distilled[k]) for k in warm)
    refits = [actor_weights(run / f"model_refit{k}.pt") for k in (1, 2)]
    assert not all(torch.equal(refits[0][k], refits[1][k]) for k in warm)
    assert not (run / "model_refit3.pt").exists()
    assert any("distillation epoch 2/2" in line for line in lines)
    assert any("drive 1 days" in line for line in lines)
    # Every step is seeded: a second run distils the same actor.
    train(cfg, tmp_path / "b", log=lambda *_: None, evaluate=False)
    again = actor_weights(tmp_path / "b" / "model_distilled.pt")
    assert all(torch.equal(again[k], distilled[k]) for k in distilled)
    # The refits load as controllers, like any checkpoint.
    GCNController(run / "model_refit1.pt")


def test_ensemble_targets_are_the_normalised_geometric_mean_on_legal_actions():
    from agents.training.ensemble import ensemble_targets

    class Fixed(torch.nn.Module):
        def __init__(self, logits):
            super().__init__()
            self.value = torch.tensor(logits)

        def logits(self, obs):
            return self.value

    mask = torch.tensor([[1, 1, 0, 1]], dtype=torch.int8)
    a, b = Fixed([[0.0, 2.0, 9.0, 1.0]]), Fixed([[1.0, 0.0, 9.0, 1.0]])
    target = ensemble_targets([a, b], {"action_mask": mask})
    legal = mask.bool()
    pa = torch.log_softmax(a.value.masked_fill(~legal, -1e30), -1)
    pb = torch.log_softmax(b.value.masked_fill(~legal, -1e30), -1)
    expected = torch.softmax(((pa + pb) / 2).masked_fill(~legal, -1e30), -1)
    torch.testing.assert_close(target, expected)
    assert target[0, 2] == 0 and float(target.sum()) == pytest.approx(1.0)
    same = ensemble_targets([a, a], {"action_mask": mask})
    torch.testing.assert_close(same, torch.exp(pa))


def test_refit_actor_leaves_the_warm_start_alone():
    from agents.controllers.registry import SHIPPED_CHECKPOINT
    from agents.training.ensemble import refit_actor
    from agents.training.demonstrations import ACTOR_GROUPS

    actor = GCNController(SHIPPED_CHECKPOINT).actor
    before = {k: v.clone() for k, v in actor.state_dict().items()}
    from marl_vertiport.vertiport_v1 import raw_env

    env = raw_env(config="paper")
    env.reset(seed=1)
    rows = {k: [] for k in ACTOR_GROUPS}
    labels = []
    while len(labels) < 40:
        if env.truncations[env.agent_selection]:
            env.reset(seed=len(labels) + 2)
        obs = env.observe(env.agent_selection)
        legal = np.flatnonzero(obs["action_mask"])
        if legal.size > 1:
            for k in ACTOR_GROUPS[:3]:
                rows[k].append(obs["observation"][k])
            rows["action_mask"].append(obs["action_mask"])
            labels.append(int(legal[0]))
        env.step(int(legal[-1]))
    env.close()
    data = {k: np.stack(v) for k, v in rows.items()}
    data["label"] = np.asarray(labels)
    data["regret"] = np.zeros(len(labels), np.float32)
    pre = build_dataclass(TrainConfig, {**to_dict(TrainConfig()), "pretrain": PRETRAIN}).pretrain
    fresh, stats = refit_actor(actor, data, pre, seed=1001)
    assert all(torch.equal(before[k], v) for k, v in actor.state_dict().items())
    assert stats["samples"] == 40
    assert not all(torch.equal(before[k], v) for k, v in fresh.state_dict().items())


@pytest.mark.parametrize("extra, message", [
    ({"ensemble": {"fits": 2}, "pretrain": {**PRETRAIN, "days": 0}}, "ensemble.fits: refits the warm start"),
    ({"ensemble": {"fits": -1}}, "ensemble.fits: must be >= 0"),
    ({"ensemble": {"fits": 2, "days": 0}}, "ensemble: days, epochs and batch_size"),
    ({"ensemble": {"fits": 2, "learning_rate": 0}}, "ensemble.learning_rate"),
])
def test_bad_ensemble_settings_are_named(extra, message):
    with pytest.raises(ConfigError, match=message):
        config(**extra)
