"""The AEC env, the single-agent env and the Parallel env are one simulator: driven by the same
actions they give identical observations, masks, rewards and truncations at every step of full
days (the Parallel env's agents whose turn it is not: the no-op mask)."""

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


@pytest.mark.slow
@pytest.mark.parametrize("config, steps_m", [("paper", None), ("paper_uncertain", None),
                                             ("fleet40", 600)])
def test_aec_and_parallel_agree_on_every_step(config, steps_m):
    """One parallel step is one AEC turn: the same observation graphs for every agent, the
    acting agent's mask, rewards, truncations and infos at every step of a full day (a busy one
    on a vertiport that passes over vehicles without a decision for fleet40, its first 600 steps).
    Only the masks of agents whose turn it is not differ: the no-op alone in the Parallel env."""
    seed = 11
    short = {} if steps_m is None else {"schedule.episode_steps": steps_m}
    aec = vertiport_v1.env(config=config, **short)
    par = vertiport_v1.parallel_env(config=config, **short)
    aec.reset(seed=seed)
    par_obs, par_infos = par.reset(seed=seed)
    assert par_infos == {a: {} for a in par.possible_agents}
    noop_mask = np.zeros_like(par_obs["evtol_0"]["action_mask"])
    noop_mask[par.noop_action] = 1
    rng = np.random.default_rng(seed)
    steps = 0
    for agent in aec.agent_iter():
        _, _, termination, truncation, _ = aec.last()
        if termination or truncation:
            aec.step(None)
            continue
        assert par.acting_agent == agent, f"turns differ at step {steps}"
        for other in aec.agents:
            aec_obs = aec.observe(other)
            assert data_equivalence(aec_obs["observation"], par_obs[other]["observation"]), \
                f"{other}'s observation differs at step {steps}"
            expected_mask = aec_obs["action_mask"] if other == agent else noop_mask
            np.testing.assert_array_equal(par_obs[other]["action_mask"], expected_mask)
        action = busy_action(aec.observe(agent), rng)
        actions = dict.fromkeys(par.agents, par.noop_action)
        actions[agent] = action
        aec.step(action)
        par_obs, rewards, terminations, truncations, infos = par.step(actions)
        assert rewards == aec.rewards, f"rewards differ at step {steps}"
        assert truncations == aec.truncations and terminations == aec.terminations
        assert data_equivalence(infos, aec.infos), f"infos differ at step {steps}"
        steps += 1
    assert steps == aec.unwrapped.config.schedule.episode_steps
    assert par.agents == [] and "episode" in infos[agent]
