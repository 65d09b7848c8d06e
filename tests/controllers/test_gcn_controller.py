"""A checkpoint as a controller: weights that do not fit or are not finite are refused, and
checkpoints joined by + play as their ensemble."""

import re

import numpy as np
import pytest
import torch

from agents.controllers.registry import SHIPPED_CHECKPOINT
from agents.controllers.gcn import CheckpointError, GCNController

torch.set_num_threads(1)


# ------------------------------------------------------------------ distribution


def test_checkpoint_with_non_finite_weights_is_refused_naming_the_weight(tmp_path):
    data = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    name = sorted(data["actor_state_dict"])[3]
    data["actor_state_dict"][name] = data["actor_state_dict"][name].clone().fill_(float("nan"))
    torch.save(data, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match=f"weight '{re.escape(name)}' has NaN or infinite"):
        GCNController(tmp_path / "nan.pt")
    data = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    data["actor_state_dict"].pop(name)
    torch.save(data, tmp_path / "short.pt")
    with pytest.raises(CheckpointError, match="do not fit the GCN actor") as exc:
        GCNController(tmp_path / "short.pt")
    assert "\n" not in str(exc.value)

def _observations(n: int = 12) -> list[dict]:
    """AEC observations with a choice (two or more legal actions) from a random day of `paper`."""
    from marl_vertiport.vertiport_v1 import raw_env

    env = raw_env(config="paper")
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    out = []
    while len(out) < n:
        obs = env.observe(env.agent_selection)
        if obs["action_mask"].sum() > 1:
            out.append(obs)
        env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    env.close()
    return out

def test_an_ensemble_takes_the_legal_action_of_largest_mean_log_probability(tmp_path):
    """`a.pt+b.pt` is the ensemble of both checkpoints: with itself a checkpoint plays as
    alone; with another, the action is the argmax of the members' mean log-probabilities."""
    from agents.controllers.registry import AgentSpecError, make_controller
    from agents.gcn.distribution import masked_logits
    from agents.controllers.gcn import GCNController, GCNEnsemble

    data = torch.load(SHIPPED_CHECKPOINT, weights_only=True)
    gen = torch.Generator().manual_seed(0)
    data["actor_state_dict"] = {k: v + 0.3 * torch.randn(v.shape, generator=gen)
                                for k, v in data["actor_state_dict"].items()}
    other = tmp_path / "other.pt"
    torch.save(data, other)
    alone, second = GCNController(SHIPPED_CHECKPOINT), GCNController(other)
    twice = make_controller(f"{SHIPPED_CHECKPOINT}+{SHIPPED_CHECKPOINT}")
    pair = make_controller(f"gcn+{other}")
    assert isinstance(pair, GCNEnsemble) and pair.name.startswith("gcn-ensemble:")
    disagree = 0
    for obs in _observations():
        assert twice.act(obs) == alone.act(obs)
        logps = []
        for member in (alone, second):
            t = member.checked_tensors(obs)
            logps.append(torch.log_softmax(masked_logits(member.actor.logits(t),
                                                         t["action_mask"]), -1)[0])
        expected = int(torch.where(torch.as_tensor(obs["action_mask"], dtype=torch.bool),
                                   (logps[0] + logps[1]) / 2, -torch.inf).argmax())
        assert pair.act(obs) == expected and obs["action_mask"][expected] == 1
        disagree += alone.act(obs) != second.act(obs)
    assert disagree > 0  # the members differ, so the check above compares something
    with pytest.raises(AgentSpecError, match="missing.pt"):
        make_controller(f"gcn+{tmp_path / 'missing.pt'}")
    with pytest.raises(Exception, match="two or more"):
        GCNEnsemble([SHIPPED_CHECKPOINT])
