"""The flat Box observation (marl_vertiport/flat.py, the one flattener): its column layout, its
bounds on busy and random days of every shipped config, the Gymnasium id, SuperSuit's
observation wrappers and vector envs on the flat Parallel env, and the AEC flattener RLlib's
adapter uses. SB3's MaskablePPO on it: tests/tools/test_interop.py."""

from importlib import resources

import gymnasium
import numpy as np
import pytest
import supersuit as ss
from gymnasium.utils.env_checker import check_env

import marl_vertiport  # noqa: F401  (registers the Gymnasium ids)
from helpers import busy_action
from marl_vertiport import vertiport_v1
from marl_vertiport.flat import (
    FlatAEC, FlatObservation, FlatParallel, flat_bounds, flat_columns, flatten_arrays,
    flatten_observation,
)
from marl_vertiport.gym_env import VertiportEnv

SHIPPED = sorted(p.name[:-5] for p in resources.files("marl_vertiport").joinpath("configs").iterdir()
                 if p.name.endswith(".yaml"))


def test_the_columns_are_the_graphs_and_the_mask_end_to_end():
    env = FlatObservation(VertiportEnv(config="paper"))
    flat, info = env.reset(seed=2)
    sim = env.unwrapped.sim
    raw = env.unwrapped._builder.observe(sim.acting)
    n, p, a = sim.n, sim.layout.n_nodes, sim.actions.n
    assert flat.shape == (13 * n + 4 * p + 11 + a,) == env.observation_space.shape
    assert len(env.columns) == flat.shape[0] == len(flat_columns(sim))
    cols = {name: i for i, name in enumerate(env.columns)}
    graph = raw["observation"]
    assert flat[cols["evtol_nodes[2].battery_pct"]] == graph["evtol_nodes"][2, 1]
    assert flat[cols["port_nodes[3].y_m"]] == graph["port_nodes"][3, 3]
    assert flat[cols["self.delay_min"]] == graph["self"][9]
    mask_cols = slice(cols["action_mask[stay]"], cols["action_mask[avoid_collision]"] + 1)
    np.testing.assert_array_equal(flat[mask_cols], raw["action_mask"])
    np.testing.assert_array_equal(info["action_mask"], raw["action_mask"])
    np.testing.assert_array_equal(env.action_masks(), raw["action_mask"])
    np.testing.assert_array_equal(flatten_observation(raw), flat)
    low, high = flat_bounds(sim)
    assert np.isfinite(low).all() and np.isfinite(high).all() and (low < high).all()


@pytest.mark.slow
@pytest.mark.parametrize("config", SHIPPED)
def test_bounds_hold_every_value_of_busy_and_random_days(config):
    """Nothing is clipped on a busy day and a random one of every shipped config: the bounds
    are a property of the vertiport, not a cut through its values."""
    for seed, busy in ((1, True), (2, False)):
        env = FlatObservation(VertiportEnv(config=config))
        obs, info = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        truncated = False
        while not truncated:
            assert env.observation_space.contains(obs)
            if busy:
                action = busy_action(env.unwrapped._builder.observe(env.unwrapped.sim.acting), rng)
            else:
                action = int(rng.choice(np.flatnonzero(info["action_mask"])))
            obs, _, _, truncated, info = env.step(action)
        assert env.clipped == 0, f"{config}: {env.clipped} values clipped (seed {seed})"


def test_a_value_out_of_bounds_is_clipped_and_counted():
    env = FlatObservation(VertiportEnv(config="paper"))
    env.reset(seed=0)
    obs = env.unwrapped._builder.observe(0)
    obs["observation"]["self"][1] = 250.0  # battery_pct above 100
    out = env.observation(obs)
    assert out[env.columns.index("self.battery_pct")] == 100.0 and env.clipped == 1


@pytest.mark.filterwarnings("ignore:.*is different from the unwrapped version.*:UserWarning")
def test_the_flat_gymnasium_id_passes_gymnasiums_checker():
    env = gymnasium.make("marl_vertiport/VertiportFlat-v1", config="paper_uncertain")
    assert isinstance(env.observation_space, gymnasium.spaces.Box)
    check_env(env, skip_render_check=True)
    with pytest.raises(TypeError, match="vertiport env"):
        FlatObservation(gymnasium.make("CartPole-v1"))


def test_supersuits_observation_wrappers_and_vector_envs_run_on_the_flat_parallel_env():
    steps = 40
    env = FlatParallel(vertiport_v1.parallel_env(config="paper", **{"schedule.episode_steps": steps}))
    d = env.observation_space("evtol_0").shape[0]
    env = ss.frame_stack_v1(ss.normalize_obs_v0(ss.dtype_v0(ss.flatten_v0(env), np.float32),
                                                env_min=-1.0, env_max=1.0), 2)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), 2, num_cpus=0,
                                 base_class="gymnasium")
    obs, infos = venv.reset(seed=0)
    assert obs.shape == (8, 2 * d) and obs.dtype == np.float32
    rng = np.random.default_rng(0)
    for _ in range(steps + 3):
        assert (obs >= -1.0).all() and (obs <= 1.0).all()
        masks = [info["action_mask"] for info in infos]
        obs, _, _, _, infos = venv.step(np.array([rng.choice(np.flatnonzero(m)) for m in masks]))


def test_a_cleanrl_style_vector_env_of_the_flat_id_carries_the_masks_in_its_infos():
    """CleanRL's scripts build ``gymnasium.vector.SyncVectorEnv`` of ``gymnasium.make(env_id)``
    and read arrays: the flat id gives a (num_envs, D) Box and the masks in the infos."""
    envs = gymnasium.vector.SyncVectorEnv(
        [lambda: gymnasium.make("marl_vertiport/VertiportFlat-v1", config="paper",
                                **{"schedule.episode_steps": 30}) for _ in range(2)])
    obs, infos = envs.reset(seed=0)
    n_actions = envs.single_action_space.n
    assert obs.shape == (2, envs.single_observation_space.shape[0])
    rng = np.random.default_rng(0)
    for _ in range(35):  # through the day's end: the vector env resets each copy
        masks = infos["action_mask"]
        assert masks.shape == (2, n_actions)
        np.testing.assert_array_equal(obs[:, -n_actions:], masks)
        obs, _, _, _, infos = envs.step(np.array([rng.choice(np.flatnonzero(m)) for m in masks]))


AEC_STEPS = 64
AEC_DAY = {"schedule.episode_steps": AEC_STEPS}


def test_the_aec_flattener_carries_the_graph_the_mask_and_the_state():
    """FlatAEC (RLlib's PettingZooEnv reads it): the flat layout's graph columns, clipped into
    their bounds, the mask apart, and state() flattened for a centralised critic."""
    inner = vertiport_v1.env(config="paper", **AEC_DAY)
    env = FlatAEC(vertiport_v1.env(config="paper", **AEC_DAY), with_state=True)
    inner.reset(seed=3)
    env.reset(seed=3)
    space = env.observation_space("evtol_0")
    assert set(space.spaces) == {"action_mask", "observations", "state"}
    assert space["observations"].shape == (4 * 13 + 10 * 4 + 11,)
    assert space["state"].shape == (3 + 4 * 17 + 10 * 5,)
    rng = np.random.default_rng(0)
    steps = 0
    for agent in env.agent_iter():
        obs, _, term, trunc, _ = env.last()
        nested = inner.observe(agent)
        assert space.contains(obs)
        np.testing.assert_array_equal(obs["action_mask"], nested["action_mask"])
        np.testing.assert_array_equal(
            obs["observations"], flatten_arrays(nested["observation"], ("evtol_nodes", "port_nodes", "self")))
        np.testing.assert_array_equal(
            obs["state"], flatten_arrays(inner.state(), ("clock", "evtol_nodes", "port_nodes")))
        action = None if term or trunc else int(rng.choice(np.flatnonzero(obs["action_mask"])))
        env.step(action)
        inner.step(action)
        steps += action is not None
    assert steps == AEC_STEPS


def test_the_aec_flattener_passes_pettingzoo_api_test():
    from pettingzoo.test import api_test

    api_test(FlatAEC(vertiport_v1.env(config="paper", **AEC_DAY), with_state=True),
             num_cycles=2 * AEC_STEPS)


def test_the_old_path_of_the_aec_flattener_still_imports_with_a_note():
    import importlib
    import sys

    import agents.common.names as names

    names._noted.clear()
    sys.modules.pop("agents.interop.flat", None)
    with pytest.warns(names.RenamedWarning, match="marl_vertiport.flat.FlatAEC"):
        module = importlib.import_module("agents.interop.flat")
    assert module.FlatObservation is FlatAEC and module.flatten is flatten_arrays
