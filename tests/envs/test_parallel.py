"""The PettingZoo Parallel env (one parallel step = one ATC turn): PettingZoo's Parallel checkers,
its rules for the agents whose turn it is not, its errors, and SuperSuit's vector envs on it.
Step-by-step parity with the AEC env is in test_parity.py."""

import numpy as np
import pytest
import supersuit as ss
from pettingzoo.test import parallel_api_test, parallel_seed_test
from pettingzoo.utils.conversions import aec_to_parallel

from marl_vertiport import IllegalActionError, vertiport_v0, vertiport_v1

SHORT = {"schedule.episode_steps": 60}


@pytest.mark.parametrize("module", [vertiport_v1, vertiport_v0])
@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
def test_pettingzoo_parallel_api(module, config):
    parallel_api_test(module.parallel_env(config=config), num_cycles=1500)


def test_pettingzoo_parallel_seed():
    parallel_seed_test(lambda: vertiport_v1.parallel_env(config="paper_uncertain"),
                       num_cycles=200)


def test_only_the_acting_agent_has_a_choice_and_the_others_wait():
    env = vertiport_v1.parallel_env(config="paper", **SHORT)
    assert env.metadata["name"] == "vertiport_v1" and env.metadata["is_parallelizable"]
    obs, _ = env.reset(seed=4)
    noop = env.noop_action
    assert noop == 2 + env.sim.layout.n_nodes  # continue
    for _ in range(40):
        acting = env.acting_agent
        for agent in env.agents:
            mask = obs[agent]["action_mask"]
            if agent == acting:
                v = env.agent_name_mapping[agent]
                np.testing.assert_array_equal(mask, env.sim.action_mask(v))
            else:
                assert np.flatnonzero(mask).tolist() == [noop]
            # An unmasked sample is legal: the seed test and random play depend on it.
            assert mask[env.action_space(agent).sample()] == 1
        actions = {a: env.action_space(a).sample(mask=obs[a]["action_mask"]) for a in env.agents}
        obs, rewards, *_ = env.step(actions)
        assert all(r == 0.0 for a, r in rewards.items() if a != acting)
    # The turns go round the fleet in the paper's order.
    assert env.acting_agent == f"evtol_{40 % 4}"


def test_bad_actions_get_named_errors_and_change_nothing():
    env = vertiport_v1.parallel_env(config="paper", **SHORT)
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    with pytest.raises(RuntimeError, match="reset"):
        env.state()
    obs, _ = env.reset(seed=0)
    acting = env.acting_agent
    other = next(a for a in env.agents if a != acting)
    before = env.state()
    legal = int(np.flatnonzero(obs[acting]["action_mask"])[0])
    with pytest.raises(IllegalActionError, match=f"{other}.*turn of {acting}.*wait"):
        env.step({acting: legal, other: 1})
    with pytest.raises(IllegalActionError, match=f"{other}"):
        env.step({acting: legal, other: np.bool_(True)})
    with pytest.raises(KeyError, match=f"no action for {acting}"):
        env.step({other: env.noop_action})
    with pytest.raises(KeyError, match="unknown agent 'evtol_9'"):
        env.step({acting: legal, "evtol_9": env.noop_action})
    with pytest.raises(TypeError, match="dict of actions"):
        env.step([legal])
    masked = int(np.flatnonzero(obs[acting]["action_mask"] == 0)[0])
    with pytest.raises(IllegalActionError, match="masked out"):
        env.step({acting: masked})
    after = env.state()
    assert all(np.array_equal(before[k], after[k]) for k in before), "a refused step changed the state"
    assert env.sim.step_count == 0
    # Agents left out of the dict (or given None) wait; numpy integers are actions.
    env.step({acting: np.int64(legal), other: None})
    for _ in range(SHORT["schedule.episode_steps"] - 1):
        a = env.acting_agent
        env.step({a: int(np.flatnonzero(env.action_mask(env.agent_name_mapping[a]))[0])})
    assert env.agents == []
    with pytest.raises(RuntimeError, match="episode ended"):
        env.step({acting: legal})


def test_pettingzoos_own_conversion_is_refused_and_says_why():
    """aec_to_parallel would make a parallel step a whole round of turns, with actions chosen
    before earlier turns change the masks: the AEC env keeps refusing it."""
    with pytest.raises(AssertionError, match="parallelizable"):
        aec_to_parallel(vertiport_v1.env(config="paper"))


def test_supersuit_vector_envs_step_through_episode_ends():
    env = vertiport_v1.parallel_env(config="paper", **SHORT)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), 2, num_cpus=0,
                                 base_class="gymnasium")
    assert venv.num_envs == 8  # 4 agents x 2 copies
    obs, _ = venv.reset(seed=0)
    assert obs["action_mask"].shape == (8, env.sim.actions.n)
    assert obs["observation"]["evtol_nodes"].shape == (8, 4, 13)
    # The two copies start from different days.
    assert not np.array_equal(obs["observation"]["evtol_nodes"][0],
                              obs["observation"]["evtol_nodes"][4])
    rng = np.random.default_rng(0)
    truncations = 0
    total = 0.0
    for _ in range(2 * SHORT["schedule.episode_steps"] + 5):
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in obs["action_mask"]])
        obs, rewards, terminated, truncated, _ = venv.step(actions)
        truncations += int(truncated.sum())
        total += float(np.abs(rewards).sum())
        assert not terminated.any()
        # Each copy has exactly one agent with a choice beyond the no-op, or none at all.
        for copy in range(2):
            masks = obs["action_mask"][4 * copy:4 * copy + 4]
            assert (masks.sum(axis=1) > 1).sum() <= 1
    assert truncations == 2 * 8  # two day ends, every agent of both copies
    assert total > 0
