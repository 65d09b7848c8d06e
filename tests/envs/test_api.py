"""The standard checkers of PettingZoo and Gymnasium on both envs."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo import AECEnv
from pettingzoo.test import api_test, render_test, seed_test

import marl_vertiport  # noqa: F401  (registers the Gymnasium id)
from marl_vertiport import vertiport_v1
from marl_vertiport.gym_env import VertiportEnv


@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
def test_pettingzoo_api(config):
    api_test(vertiport_v1.env(config=config), num_cycles=300)


def test_pettingzoo_seed():
    seed_test(lambda: vertiport_v1.env(config="paper_uncertain"), num_cycles=200)


@pytest.mark.filterwarnings("ignore:render_mode='human' needs a display:UserWarning")
def test_pettingzoo_render():
    render_test(lambda render_mode=None: vertiport_v1.env(render_mode=render_mode))


@pytest.mark.filterwarnings("ignore:.*Box observation space m.*:UserWarning")
@pytest.mark.filterwarnings("ignore:render_mode='human' needs a display:UserWarning")
@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
def test_gymnasium_check_env(config):
    env = gymnasium.make("marl_vertiport/Vertiport-v1", config=config).unwrapped
    check_env(env, skip_render_check=False)


def test_gymnasium_make_and_episode_end():
    env = gymnasium.make("marl_vertiport/Vertiport-v1", config="paper",
                         **{"schedule.episode_steps": 30})
    obs, info = env.reset(seed=3)
    assert "agent" in info
    rng = np.random.default_rng(0)
    for step in range(30):
        action = int(rng.choice(np.flatnonzero(obs["action_mask"])))
        obs, reward, terminated, truncated, info = env.step(action)
        assert not terminated
        assert truncated == (step == 29)
    assert info["episode"]["steps"] == 30


def test_rgb_frame_shows_the_scene():
    env = vertiport_v1.env(render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (360, 480, 3) and frame.dtype == np.uint8
    # Not a blank image: ground, ports and vehicles give many distinct colours.
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 20
    env.close()


def test_human_mode_without_display_warns_and_runs(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.warns(UserWarning, match="display"):
        env = vertiport_v1.env(render_mode="human")
    env.reset(seed=0)
    assert env.render() is None
    env.close()


def test_unknown_render_mode():
    with pytest.raises(ValueError, match="render_mode"):
        vertiport_v1.env(render_mode="ansi")


def test_spaces_are_cached_and_contain_observations():
    env = vertiport_v1.env()
    env.reset(seed=1)
    agent = env.agents[0]
    assert env.observation_space(agent) is env.observation_space(agent)
    assert env.observation_space(agent).contains(env.observe(agent))
    assert env.unwrapped.state_space.contains(env.state())
    assert env.observe(agent)["action_mask"].dtype == np.int8
    # 4 + 2 normal + 1 charging + 7 hover spots = 14 actions (paper's table I).
    assert env.action_space(agent).n == 14


def test_single_agent_sample_is_legal_and_copies_are_plain():
    import copy
    import pickle

    env = VertiportEnv()
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(200):
        action = env.action_space.sample()
        assert obs["action_mask"][action] == 1
        obs, *_ = env.step(action)
    assert type(copy.deepcopy(env.action_space)) is gymnasium.spaces.Discrete
    assert pickle.loads(pickle.dumps(env.action_space)) == gymnasium.spaces.Discrete(14)


def test_last_through_the_wrapper_is_the_raw_envs_last():
    from pettingzoo.utils import wrappers

    env = vertiport_v1.env(config="paper_uncertain")
    assert isinstance(env, wrappers.OrderEnforcingWrapper)
    assert str(env) == "vertiport_v1"
    with pytest.raises(AttributeError, match="before reset"):
        env.last()
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(200):
        got, want = env.last(), AECEnv.last(env)  # the inherited last(), through __getattr__
        np.testing.assert_equal(got, want)
        assert env.last(observe=False)[0] is None
        legal = np.flatnonzero(got[0]["action_mask"])
        env.step(int(rng.choice(legal)))
    env.close()


def test_the_wrappers_step_and_iterator_are_pettingzoos(caplog):
    """Our one-hop step() and agent iterator give the agents, errors and warnings of the
    inherited ones (PettingZoo's OrderEnforcingWrapper read through __getattr__)."""
    from pettingzoo.utils import wrappers

    from marl_vertiport.vertiport_v1 import raw_env

    ours, theirs = vertiport_v1.env(config="small"), wrappers.OrderEnforcingWrapper(raw_env(config="small"))
    for env in (ours, theirs):
        with pytest.raises(AssertionError, match="before step"):
            env.step(0)
        with pytest.raises(AssertionError, match="before agent_iter"):
            env.agent_iter()
    seen = []
    for env in (ours, theirs):
        env.reset(seed=5)
        rng, agents = np.random.default_rng(1), []
        for agent in env.agent_iter(300):
            obs, _, term, trunc, _ = env.last()
            agents.append(agent)
            env.step(None if term or trunc else int(rng.choice(np.flatnonzero(obs["action_mask"]))))
        seen.append(agents)
        it = iter(env.agent_iter())
        next(it)
        with pytest.raises(AssertionError, match="step"):  # no step between two agents
            next(it)
        env.agents.clear()  # as after the last agent's final step
        caplog.clear()
        env.step(0)
        assert "Should reset() first" in caplog.text
        assert list(env.agent_iter()) == []
    assert seen[0] == seen[1] and len(seen[0]) == 300


def test_api_edges_get_clear_errors():
    """Before reset, an unknown agent id, a step after truncation, and state() through
    gymnasium.make: each either works as documented or says what to do."""
    import gymnasium

    from marl_vertiport.vertiport_v1 import raw_env

    raw = raw_env(config="small")
    for call in (raw.state, lambda: raw.observe("evtol_0")):
        with pytest.raises(RuntimeError, match=r"reset\(\) must be called before"):
            call()
    raw.reset(seed=0)
    with pytest.raises(KeyError, match="unknown agent 'evtl_0'; the agents are evtol_0, evtol_1, evtol_2"):
        raw.observe("evtl_0")
    raw.close()

    env = gymnasium.make("marl_vertiport/Vertiport-v1", config="small", schedule__episode_steps=2)
    with pytest.raises(RuntimeError, match=r"reset\(\) must be called before state"):
        env.state()
    env.reset(seed=0)
    assert set(env.state()) == {"port_nodes", "evtol_nodes", "clock"}
    truncated = False
    while not truncated:
        *_, truncated, _ = env.step(int(np.flatnonzero(env.action_masks())[0]))
    minute = env.unwrapped.sim.minute
    with pytest.raises(RuntimeError, match=r"episode ended \(truncated after 2 steps\); call reset"):
        env.step(0)
    assert env.unwrapped.sim.minute == minute  # nothing simulated after the end
    env.close()


def test_one_observation_path_for_one_vehicle_and_for_rows_of_them():
    """ObservationBuilder.observe (both envs) and observe_into / state_into (the training
    vector env) build the same graphs: row r of a batch is vehicle r's observation, a row of no
    vehicle (-1) has the graphs without is_self and its own features untouched, and the state
    rows differ from state() only in whom is_self marks."""
    from marl_vertiport.sim.schema import EVTOL_FEATURES, SELF_FEATURES
    from marl_vertiport.spaces import ObservationBuilder

    env = vertiport_v1.env(config="paper_uncertain")
    env.reset(seed=4)
    for _ in range(37):  # into the day: vehicles flying, noise drawn
        obs = env.observe(env.agent_selection)
        env.step(int(np.flatnonzero(obs["action_mask"])[0]))
    sim = env.unwrapped.sim
    builder = ObservationBuilder(sim)
    n, p = sim.n, sim.layout.n_nodes
    observers = [2, 0, -1, 3, 1]
    ports = np.full((5, p + 2, 4), 7.0, np.float32)
    evtols = np.full((5, n + 1, len(EVTOL_FEATURES)), 7.0, np.float32)
    own = np.full((5, len(SELF_FEATURES)), 7.0, np.float32)
    builder.observe_into(observers, ports, evtols, own)
    is_self = EVTOL_FEATURES.index("is_self")
    for row, v in enumerate(observers):
        assert (ports[row, p:] == 7.0).all() and (evtols[row, n:] == 7.0).all()  # padding kept
        if v < 0:
            assert (evtols[row, :n, is_self] == 0).all() and (own[row] == 7.0).all()
            continue
        single = env.observe(f"evtol_{v}")["observation"]
        np.testing.assert_array_equal(ports[row, :p], single["port_nodes"])
        np.testing.assert_array_equal(evtols[row, :n], single["evtol_nodes"])
        np.testing.assert_array_equal(own[row], single["self"])
    state = env.state()
    st_ports = np.zeros((5, p, 5), np.float32)
    st_evtols = np.zeros((5, n, state["evtol_nodes"].shape[-1]), np.float32)
    clock = np.zeros((5, 3), np.float32)
    builder.state_into(observers, st_ports, st_evtols, clock)
    for row, v in enumerate(observers):
        expected = state["evtol_nodes"].copy()
        expected[:, is_self] = 0.0
        if v >= 0:
            expected[v, is_self] = 1.0
        np.testing.assert_array_equal(st_evtols[row], expected)
        np.testing.assert_array_equal(st_ports[row], state["port_nodes"])
        np.testing.assert_array_equal(clock[row], state["clock"])
    # The simulator's cached graph features are read-only: an observation is always a copy.
    assert not sim.evtol_features().flags.writeable and not sim.port_features().flags.writeable
