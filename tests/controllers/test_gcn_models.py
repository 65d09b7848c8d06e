"""The learned ATC's network: the masked distribution and the GCN models (shapes, permutation
invariance, sharpening)."""


import pytest
import torch
from tensordict import TensorDict

from agents.gcn.distribution import MaskedCategorical
from agents.gcn.models import GraphActor, GraphCritic
from agents.gcn.features import feature_names
from agents.gcn.features import POLICY_GROUPS, STATE_GROUPS
from agents.training.vec_env import MultiAgentVecEnv

torch.set_num_threads(1)


# ------------------------------------------------------------------ distribution


def test_masked_categorical_matches_torch_on_hand_made_logits():
    logits = torch.tensor([[1.0, 2.0, 0.5, -1.0], [0.0, 0.0, 3.0, 1.0]])
    mask = torch.tensor([[True, False, True, True], [False, True, True, False]])
    dist = MaskedCategorical(1, 4)
    dist.update(logits, mask)
    for row in range(2):
        legal = mask[row]
        ref = torch.distributions.Categorical(logits=logits[row][legal])
        torch.testing.assert_close(dist.probs[row][legal], ref.probs)
        assert (dist.probs[row][~legal] == 0).all()
        torch.testing.assert_close(dist.entropy[row], ref.entropy())
        legal_idx = torch.nonzero(legal).squeeze(-1)
        lp = dist.log_prob(legal_idx[:, None].float().T.reshape(-1, 1)[:1].expand(2, 1))
        assert torch.isfinite(lp).all()
        for k, action in enumerate(legal_idx.tolist()):
            actions = torch.full((2, 1), float(action))
            torch.testing.assert_close(dist.log_prob(actions)[row], ref.log_prob(torch.tensor(k)))
    # row 0: probabilities of the legal logits (1, 0.5, -1) after softmax
    expected = torch.softmax(torch.tensor([1.0, 0.5, -1.0]), 0)
    torch.testing.assert_close(dist.probs[0, [0, 2, 3]], expected)
    assert dist.kl_divergence(dist.params, dist.params).abs().max() < 1e-6

def test_masked_categorical_never_samples_a_masked_action():
    torch.manual_seed(0)
    dist = MaskedCategorical(1, 6)
    logits = torch.randn(512, 6) * 3
    mask = torch.rand(512, 6) > 0.5
    mask[:, 0] = True
    dist.update(logits, mask)
    for _ in range(20):
        a = dist.sample().long().squeeze(-1)
        assert mask[torch.arange(512), a].all()
    assert mask[torch.arange(512), dist.deterministic_output(logits, mask).long().squeeze(-1)].all()
    assert torch.isfinite(dist.entropy).all()

def example_obs(batch: int, seed: int = 0) -> TensorDict:
    env = MultiAgentVecEnv("paper", num_envs=batch, seed=seed)
    obs = env.get_observations()
    env.close()
    return obs

def test_actor_and_critic_shapes_on_batched_graphs():
    obs = example_obs(3)  # 3 copies x 4 eVTOLs = 12 rows
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    critic = GraphCritic(obs, {"critic": list(STATE_GROUPS)}, "critic", 1, feature_names("state"))
    assert actor(obs).shape == (12, 1) and actor(obs, stochastic_output=True).shape == (12, 1)
    assert actor.get_output_log_prob(actor(obs, stochastic_output=True)).shape == (12,)
    assert actor.output_entropy.shape == (12,)
    assert actor.action_probabilities(obs).shape == (12, 14)
    assert critic(obs).shape == (12, 1)

def test_sharpening_divides_every_logit_and_keeps_the_greedy_actions():
    torch.manual_seed(2)
    obs = example_obs(3)
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    actor.eval()
    with torch.no_grad():
        before, greedy = actor.logits(obs), actor(obs)
        actor.action_probabilities(obs)
        entropy = actor.distribution.entropy.clone()
        actor.sharpen(0.25)
        torch.testing.assert_close(actor.logits(obs), before / 0.25)
        assert torch.equal(actor(obs), greedy)
        actor.action_probabilities(obs)
        assert (actor.distribution.entropy <= entropy + 1e-6).all()
        assert (actor.distribution.entropy < entropy).any()
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="temperature"):
            actor.sharpen(bad)

def test_gcn_output_is_invariant_to_the_order_of_the_fleet():
    torch.manual_seed(1)
    obs = example_obs(2)
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    critic = GraphCritic(obs, {"critic": list(STATE_GROUPS)}, "critic", 1, feature_names("state"))
    perm = torch.tensor([2, 0, 3, 1])
    shuffled = obs.clone()
    shuffled["evtol_nodes"] = obs["evtol_nodes"][:, perm]
    shuffled["state_evtol_nodes"] = obs["state_evtol_nodes"][:, perm]
    with torch.no_grad():
        torch.testing.assert_close(actor.logits(shuffled), actor.logits(obs))
        torch.testing.assert_close(critic(shuffled), critic(obs))

def test_reordering_nodes_of_a_type_permutes_the_node_action_probabilities():
    """Hover spots (nodes 3-9 of the paper layout) listed in another order: the probability of
    "go to spot k" moves with spot k; the other actions keep theirs."""
    torch.manual_seed(2)
    obs = example_obs(2)
    actor = GraphActor(obs, {"actor": list(POLICY_GROUPS)}, "actor", 1, feature_names("observation"))
    perm = torch.tensor([0, 1, 2, 5, 9, 3, 8, 4, 7, 6])  # new node j is old node perm[j]
    cols = torch.cat([torch.tensor([0, 1]), perm + 2, torch.tensor([12, 13])])
    shuffled = obs.clone()
    shuffled["port_nodes"] = obs["port_nodes"][:, perm]
    shuffled["action_mask"] = obs["action_mask"][:, cols]
    # a hovering row makes the spots legal actions
    shuffled["action_mask"][:, 2:12] = True
    full = obs.clone()
    full["action_mask"][:, 2:12] = True
    with torch.no_grad():
        p = actor.action_probabilities(full)
        q = actor.action_probabilities(shuffled)
    torch.testing.assert_close(q, p[:, cols])
    assert not torch.allclose(p[:, 5], p[:, 6])  # the spots are told apart (by position)
