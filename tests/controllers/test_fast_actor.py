"""The GCN actor's NumPy forward pass, which the greedy GCN controller plays, gives the torch
actor's logits and greedy actions on any layout; a sampling controller has no greedy copy."""

import numpy as np
import pytest
import torch
from helpers import busy_action, small_actor

from agents.controllers.gcn import GCNController
from agents.controllers.registry import SHIPPED_CHECKPOINT
from agents.gcn.fast import FastGraphActor
from marl_vertiport.vertiport_v1 import raw_env

torch.set_num_threads(1)


def _busy_observations(config: str, steps: int, seed: int = 3) -> list[dict]:
    """The acting vehicle's observation at each step of a day of ``config`` flown with busy
    random legal actions (vehicles in every status)."""
    env = raw_env(config=config)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        obs = env.observe(env.agent_selection)
        out.append(obs)
        env.step(busy_action(obs, rng))
    env.close()
    return out


@pytest.mark.parametrize("config", ["paper", "mid", "large"])
def test_numpy_logits_are_the_torch_actors_on_every_layout(config):
    shipped = GCNController(SHIPPED_CHECKPOINT)
    random_weights = GCNController.__new__(GCNController)
    random_weights.actor = small_actor().eval()
    observations = _busy_observations(config, 200)
    statuses = set()
    for source in (shipped, random_weights):
        fast = FastGraphActor(source.actor)
        for obs in observations:
            with torch.no_grad():
                want = source.actor.logits(GCNController._tensors(obs))[0].numpy()
            got = fast.logits(obs)
            assert got.shape == want.shape and got.dtype == np.float32
            np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())
            legal = np.flatnonzero(obs["action_mask"])
            assert fast.act(obs) == legal[np.argmax(want[legal])]
            statuses.add(int(obs["observation"]["self"][0]))
    assert len(statuses) >= 4  # on the ground, hovering, in transit, away


def test_the_greedy_controller_and_its_copy_play_the_torch_actors_greedy_actions():
    shipped = GCNController(SHIPPED_CHECKPOINT)
    fast = shipped.fast()
    assert fast.pure_act and fast.name.endswith(":fast")
    for obs in _busy_observations("paper", 150):
        with torch.no_grad():
            want = int(shipped.actor(GCNController._tensors(obs)).item())
        assert shipped.act(obs) == fast.act(obs) == want
    with pytest.raises(ValueError, match="sampling"):
        GCNController(SHIPPED_CHECKPOINT, deterministic=False).fast()
    with pytest.raises(TypeError, match="GraphActor"):
        FastGraphActor(torch.nn.Linear(2, 2))
