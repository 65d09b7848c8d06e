"""Other RL libraries on the env (agents/interop/): TorchRL's ``PettingZooWrapper`` (AEC,
``use_mask=True``) and RLlib's ``PettingZooEnv`` wrap the AEC env, and each library's own PPO
runs three iterations on 64-step days, with a centralised critic reading ``state()``.

Needs the torchrl and rllib extras (installed by `make test`); each library's tests are
skipped with the reason where its extra is absent. The flattening wrapper RLlib's adapter uses
(marl_vertiport.flat.FlatAEC) is tested with the other flatteners, tests/envs/test_flat.py."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from marl_vertiport import vertiport_v1

pytestmark = pytest.mark.filterwarnings(  # TorchRL's own classes, at import
    "ignore:Creating .*WeightUpdater.*deprecated:DeprecationWarning")

STEPS = 64  # a short day: every PPO iteration below ends at least one episode
SHORT = {"schedule.episode_steps": STEPS}

TORCHRL_MISSING = "the torchrl extra is not installed: pip install -e '.[torchrl]'"
SB3_MISSING = "the sb3 extra is not installed: pip install -e '.[sb3]'"
RLLIB_MISSING = "the rllib extra is not installed: pip install -e '.[rllib]'"


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _params(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def _changed(before: list[torch.Tensor], module: torch.nn.Module) -> bool:
    return any(not torch.equal(a, b.detach()) for a, b in zip(before, module.parameters()))


# -- TorchRL --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def torchrl_env():
    pytest.importorskip("torchrl", reason=TORCHRL_MISSING)
    from agents.interop import torchrl_env

    return torchrl_env


def test_torchrl_wrapper_one_acting_agent_a_bool_mask_and_the_state(torchrl_env):
    env = torchrl_env.make_env("paper", seed=0, **SHORT)
    assert env.group_map == {"evtol": [f"evtol_{i}" for i in range(4)]}
    assert env.full_action_spec[torchrl_env.ACTION].space.n == 14
    assert set(env.observation_spec["state"].keys()) == {"clock", "evtol_nodes", "port_nodes"}
    first = env.reset(seed=5)  # reset's keywords go to the AEC env's reset
    # Random legal actions (the action spec carries the acting agent's mask) to the day's end.
    data = env.rollout(STEPS + 10, auto_reset=False, tensordict=first)
    assert data.shape == (STEPS,) and bool(data["next", "done"][-1])
    acting = data[torchrl_env.ACTING]
    assert acting.sum(-1).eq(1).all()                                  # one agent a step
    assert acting.float().argmax(-1).tolist() == [t % 4 for t in range(STEPS)]  # round-robin
    assert data[torchrl_env.ACTION_MASK].dtype == torch.bool
    nested = vertiport_v1.raw_env(config="paper", **SHORT)
    nested.reset(seed=5)
    np.testing.assert_array_equal(data["state", "port_nodes"][0].numpy(), nested.state()["port_nodes"])
    np.testing.assert_array_equal(data[torchrl_env.ACTION_MASK][0, 0].numpy(),
                                  nested.observe("evtol_0")["action_mask"].astype(bool))


def test_torchrl_ppo_three_iterations(torchrl_env):
    torch.manual_seed(0)
    env = torchrl_env.make_env("paper", seed=0, **SHORT)
    actor, critic = torchrl_env.make_actor(env), torchrl_env.make_critic(env)
    assert critic.in_keys[0][0] == "state"  # centralised: the critic reads state()
    actor_before, critic_before = _params(actor), _params(critic)
    stats = list(torchrl_env.ppo(env, actor, critic, iterations=3, frames_per_batch=STEPS,
                                 epochs=2, minibatch_size=32))
    assert [s["iteration"] for s in stats] == [0, 1, 2]
    for s in stats:
        assert s["frames"] == STEPS and s["acting_steps"] == STEPS
        assert s["illegal_actions"] == 0
        assert s["episodes_ended"] == 1  # a batch of one day's steps ends exactly one day
        assert all(math.isfinite(s[k]) for k in ("loss_objective", "loss_critic", "loss_entropy"))
        assert math.isfinite(s["reward"]) and s["reward"] != 0
    assert _changed(actor_before, actor) and _changed(critic_before, critic)


@pytest.mark.parametrize("flat", [False, True])
def test_torchrl_parallel_env_as_benchmarl_builds_it_and_ppo_on_every_row(torchrl_env, flat):
    """The Parallel env in ``PettingZooWrapper`` as a BenchMARL PettingZoo task builds it (no
    ``use_mask``: every agent acts every step), nested graphs or the flat Box, and PPO on
    every agent's row with a centralised critic (MAPPO-style)."""
    torch.manual_seed(0)
    env = torchrl_env.make_parallel_env("paper", seed=0, flat=flat, **SHORT)
    assert not env.use_mask and env.group_map == {"evtol": [f"evtol_{i}" for i in range(4)]}
    obs_spec = env.observation_spec["evtol", "observation"]
    if flat:
        assert obs_spec.shape == (4, 4 * 13 + 10 * 4 + 11 + 14)
    data = env.rollout(STEPS + 10, break_when_any_done=True)
    assert data.shape == (STEPS,)
    legal = data[torchrl_env.ACTION_MASK].sum(-1)  # (steps, agents)
    # At most one agent a step has a choice; the others only the no-op.
    assert (legal > 1).sum(-1).le(1).all() and legal.ge(1).all()
    actor, critic = torchrl_env.make_actor(env), torchrl_env.make_critic(env)
    before = _params(actor) + _params(critic)
    stats = list(torchrl_env.ppo(env, actor, critic, iterations=3, frames_per_batch=STEPS,
                                 epochs=2, minibatch_size=32))
    for s in stats:
        assert s["frames"] == STEPS and s["illegal_actions"] == 0 and s["episodes_ended"] == 1
        assert all(math.isfinite(s[k]) for k in ("loss_objective", "loss_critic", "loss_entropy"))
    assert _changed(before[:len(_params(actor))], actor) and _changed(before[len(_params(actor)):], critic)


# -- Stable-Baselines3 ----------------------------------------------------------------------


def test_sb3_maskable_ppo_trains_on_the_flat_env_and_acts_legally():
    """The documented recipe: sb3-contrib's MaskablePPO ("MlpPolicy") on
    marl_vertiport/VertiportFlat-v1, a few thousand steps; its masked actions are legal."""
    pytest.importorskip("sb3_contrib", reason=SB3_MISSING)
    from stable_baselines3.common.env_checker import check_env

    from agents.interop import sb3

    env = sb3.make_env("paper", **SHORT)
    check_env(env, warn=False)
    model = sb3.train("paper", steps=2048, seed=0, n_steps=512, batch_size=128, n_epochs=2, **SHORT)
    assert model.num_timesteps == 2048
    fresh = sb3.train("paper", steps=0, seed=0, n_steps=512, **SHORT)
    assert _changed(_params(fresh.policy), model.policy)  # learning moved the weights
    obs, _ = env.reset(seed=1)
    for _ in range(STEPS):
        mask = env.unwrapped.action_masks()
        action, _ = model.predict(obs, action_masks=mask, deterministic=False)
        assert mask[int(action)] == 1
        obs, _, _, truncated, _ = env.step(int(action))
    assert truncated


# -- RLlib ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rllib_env():
    pytest.importorskip("ray.rllib", reason=RLLIB_MISSING)
    from agents.interop import rllib_env

    return rllib_env


def test_rllib_pettingzoo_env_hands_the_turn_round(rllib_env):
    env = rllib_env.make_env("paper", **SHORT)
    obs, infos = env.reset(seed=0)
    assert list(obs) == ["evtol_0"] and infos == {}
    rng = np.random.default_rng(0)
    order, returns = [], dict.fromkeys(env.possible_agents, 0.0)
    for step in range(STEPS):
        (agent,) = obs  # the one agent whose turn it is
        assert env.observation_spaces[agent].contains(obs[agent])
        order.append(agent)
        action = int(rng.choice(np.flatnonzero(obs[agent]["action_mask"])))
        obs, rewards, terms, truncs, _ = env.step({agent: action})
        for a, r in rewards.items():
            returns[a] += r
        if step < STEPS - 1:
            assert len(obs) == 1 and not truncs["__all__"]
    assert order == [f"evtol_{t % 4}" for t in range(STEPS)]
    assert set(obs) == set(env.possible_agents) and truncs["__all__"] and not terms["__all__"]
    assert all(r != 0 for r in returns.values())  # every agent's actions were rewarded


def test_rllib_module_gives_illegal_actions_probability_zero(rllib_env):
    env = rllib_env.make_env("paper", **SHORT)
    space, actions = env.observation_spaces["evtol_0"], env.action_spaces["evtol_0"]
    module = rllib_env.MaskedActorCritic(observation_space=space, action_space=actions,
                                         inference_only=False, model_config={"hidden": 16})
    rng = np.random.default_rng(0)
    mask = (rng.random((256, actions.n)) < 0.2).astype(np.int8)
    mask[np.arange(256), rng.integers(0, actions.n, 256)] = 1  # at least one legal action
    batch = {"obs": {"action_mask": torch.as_tensor(mask),
                     "observations": torch.randn(256, space["observations"].shape[0]) * 50,
                     "state": torch.randn(256, space["state"].shape[0]) * 50}}
    with torch.no_grad():
        logits = module.forward_exploration(batch)["action_dist_inputs"]
        probs = torch.softmax(logits, -1)
        values = module.compute_values(batch)
    assert torch.all(probs[torch.as_tensor(mask) == 0] == 0)
    assert torch.allclose(probs.sum(-1), torch.ones(256))
    assert values.shape == (256,) and torch.isfinite(values).all()
    samples = torch.distributions.Categorical(logits=logits).sample((20,))
    assert torch.as_tensor(mask).gather(-1, samples.T).all()


def test_rllib_ppo_three_iterations(rllib_env):
    import ray

    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False,
                 object_store_memory=80 * 1024 ** 2)
    try:
        config = rllib_env.ppo_config({"config": "paper", "overrides": SHORT}, hidden=32,
                                      batch_size=2 * STEPS, minibatch_size=STEPS, epochs=2)
        algo = config.build_algo()
        try:
            module = algo.get_module(rllib_env.MODULE_ID)
            assert isinstance(module, rllib_env.MaskedActorCritic)
            assert module.critic_key == "state"  # centralised: the critic reads state()
            before = _params(module)
            # An illegal action would raise in the env (2 of 14 actions are legal at most
            # steps), so three iterations of sampling are the legality check.
            results = [algo.train() for _ in range(3)]
            after = algo.get_module(rllib_env.MODULE_ID)
        finally:
            algo.stop()
    finally:
        if started:
            ray.shutdown()
    for r in results:
        runners, learner = r["env_runners"], r["learners"][rllib_env.MODULE_ID]
        assert runners["num_env_steps_sampled"] == 2 * STEPS
        assert runners["num_episodes"] == 2 and runners["episode_len_mean"] == STEPS
        assert math.isfinite(runners["episode_return_mean"])
        assert learner["num_module_steps_trained"] > 0
        for key in ("total_loss", "policy_loss", "vf_loss", "entropy"):
            assert math.isfinite(learner[key]), key
    assert results[-1]["num_env_steps_sampled_lifetime"] == 3 * 2 * STEPS
    assert _changed(before, after)


# -- a missing extra, and TorchRL's own Gymnasium wrapper -----------------------------------


@pytest.mark.parametrize("module, blocked, extra", [
    ("agents.interop.torchrl_env", "torchrl", "torchrl"),
    ("agents.interop.rllib_env", "ray", "rllib"),
    ("agents.interop.sb3", "sb3_contrib", "sb3"),
])
def test_an_adapter_without_its_extra_fails_at_import_with_the_install_command(module, blocked, extra):
    """Without the library, importing the adapter fails at once with one line naming the
    extra to install (the library is hidden from a fresh interpreter)."""
    code = (f"import sys; sys.modules[{blocked!r}] = None\n"
            f"try:\n    import {module}\nexcept ImportError as exc:\n    print(exc)\n"
            f"else:\n    print('imported')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert out.returncode == 0, out.stderr
    line = out.stdout.strip()
    assert line != "imported" and "\n" not in line
    assert f"install the {extra} extra, pip install -e '.[{extra}]'" in line


def test_torchrl_gymenv_builds_the_single_agent_env_by_its_id():
    """TorchRL's ``GymEnv`` passes ``frameskip`` first and drops it on a TypeError that says
    so: the env's unknown-keyword error keeps that convention."""
    pytest.importorskip("torchrl", reason=TORCHRL_MISSING)
    from torchrl.envs import GymEnv

    import marl_vertiport  # noqa: F401 (registers the id)

    env = GymEnv("marl_vertiport/Vertiport-v1", categorical_action_encoding=True, **SHORT)
    td = env.reset(seed=0)
    legal = torch.nonzero(td["action_mask"].bool()).flatten()
    td["action"] = legal[0]
    out = env.step(td)
    assert out["next", "reward"].shape == (1,)
    assert set(out["next", "observation"].keys()) == {"port_nodes", "evtol_nodes", "self"}
    env.close()
