"""The AEC env and the single-agent env are one simulator: driven by the same actions they
give identical observations, masks, rewards and truncations at every step of full days."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

from helpers import busy_action
from marl_vertiport import vertiport_v1
from marl_vertiport.gym_env import VertiportEnv


@pytest.mark.slow
@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
@pytest.mark.parametrize("seed", [0, 7, 123])
def test_aec_and_single_agent_agree_over_a_full_day(config, seed):
    aec = vertiport_v1.env(config=config)
    gym_env = VertiportEnv(config=config)
    aec.reset(seed=seed)
    gym_obs, _ = gym_env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    steps = 0
    metrics = None
    for agent in aec.agent_iter():
        obs, _, termination, truncation, info = aec.last()
        if termination or truncation:
            aec.step(None)
            continue
        assert agent == f"evtol_{steps % 4}"  # the paper's round-robin order
        assert data_equivalence(obs, gym_obs), f"observations differ at step {steps}"
        np.testing.assert_array_equal(obs["action_mask"], gym_obs["action_mask"])
        action = busy_action(obs, rng)
        aec.step(action)
        gym_obs, reward, terminated, truncated, gym_info = gym_env.step(action)
        assert aec.rewards[agent] == reward, f"rewards differ at step {steps}"
        assert aec.truncations[agent] == truncated
        assert not terminated and not aec.terminations[agent]
        steps += 1
        if truncated:
            metrics = gym_info["episode"]
            assert data_equivalence(aec.infos[agent]["episode"], metrics)
    assert steps == 1440
    # The busy policy keeps the fleet working: the day had real traffic.
    assert metrics["takeoffs"] >= 4 and metrics["completed_trips"] >= 3
