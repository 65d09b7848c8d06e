"""The vertiport AEC env in RLlib: ``PettingZooEnv``, an action-masking RLModule and a PPO
config on RLlib's new API stack. Needs the rllib extra (``pip install -e '.[rllib]'``).

What RLlib needs from the env, and what this module adds for it:

* ``PettingZooEnv`` steps the AEC env one agent at a time: each ``step`` returns the
  observation of the next agent to act, with that agent's reward for its previous action
  (the env keeps it in ``_cumulative_rewards`` until the agent acts again).
* RLlib's default PPO models read neither a nested ``Dict`` observation nor an action mask, so
  the env goes through :class:`marl_vertiport.flat.FlatAEC` (``{"action_mask",
  "observations"}``) and the policy is :class:`MaskedActorCritic`, which gives illegal
  actions probability 0 (the env raises ``ValueError`` on one).
* RLlib's ``PettingZooEnv`` does not call ``state()``. With ``with_state=True`` (the default)
  the flattened ``env.state()`` travels in every observation as ``"state"``; the
  actor never reads it, the critic does (a centralised value function).
* RLlib's env check (on by default) steps an unmasked random action, which the env rejects
  more often than not, so :func:`ppo_config` turns it off (``disable_env_checking=True``).
* One RLModule (``"shared"``) acts for every eVTOL.

A minimal run (one torch thread: several times faster than torch's default on these small
batches, docs/ecosystem.md)::

    import ray
    import torch
    torch.set_num_threads(1)
    from agents.interop.rllib_env import ppo_config

    ray.init(num_cpus=2, include_dashboard=False)
    algo = ppo_config(env_config={"config": "paper",
                                  "overrides": {"schedule.episode_steps": 64}}).build_algo()
    for _ in range(3):
        print(algo.train()["env_runners"]["episode_return_mean"])
    algo.save_to_path("runs/rllib/paper")  # or save_policy(algo, ..., env), with the columns
    algo.stop()

and every command plays the checkpoint: ``marl-vertiport evaluate --agents runs/rllib/paper
dispatcher`` (:class:`agents.controllers.foreign.RLlibController`, weights only).
"""

from __future__ import annotations

from typing import Any

from agents.interop import require
from marl_vertiport.flat import FlatAEC
from agents.common.nets import mlp, symlog
from marl_vertiport import vertiport_v1

__all__ = ["ENV_NAME", "MODULE_ID", "MaskedActorCritic", "env_creator", "make_env",
           "ppo_config", "register", "save_policy"]

EXTRA = "rllib"
ENV_NAME = "marl_vertiport/vertiport_v1"
MODULE_ID = "shared"

require("ray.rllib", EXTRA)

import torch  # noqa: E402  (after the check, so a missing ray is the one error shown)
from ray.rllib.algorithms.ppo import PPOConfig  # noqa: E402
from ray.rllib.core.columns import Columns  # noqa: E402
from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI  # noqa: E402
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec  # noqa: E402
from ray.rllib.core.rl_module.rl_module import RLModuleSpec  # noqa: E402
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule  # noqa: E402
from ray.rllib.env.wrappers.pettingzoo_env import PettingZooEnv  # noqa: E402


def make_env(config: Any = "paper", *, with_state: bool = True, **overrides: Any) -> PettingZooEnv:
    """RLlib's ``PettingZooEnv`` over the flattened AEC env; ``overrides`` as in
    ``vertiport_v1.env``."""
    return PettingZooEnv(FlatAEC(vertiport_v1.env(config=config, **overrides),
                                         with_state=with_state))


def env_creator(env_config: dict) -> PettingZooEnv:
    """``make_env`` from RLlib's ``env_config``: ``{"config": "paper", "with_state": True,
    "overrides": {"schedule.episode_steps": 64}}`` (every key optional)."""
    cfg = dict(env_config or {})
    return make_env(cfg.get("config", "paper"), with_state=cfg.get("with_state", True),
                    **dict(cfg.get("overrides", {})))


def register(name: str = ENV_NAME) -> str:
    """Register :func:`env_creator` with Ray Tune under ``name``; returns the name."""
    from ray.tune.registry import register_env

    register_env(name, env_creator)
    return name


class MaskedActorCritic(TorchRLModule, ValueFunctionAPI):
    """An MLP actor over ``"observations"`` whose illegal actions (``"action_mask"`` 0) get
    the most negative finite logit, so probability 0; an MLP critic over ``"state"`` when the
    observations carry it (centralised), otherwise over ``"observations"``.

    ``model_config``: ``{"hidden": 64}``."""

    def setup(self) -> None:
        space = self.observation_space
        config = self.model_config if isinstance(self.model_config, dict) else {}
        hidden = int(config.get("hidden", 64))
        self.critic_key = "state" if "state" in space.spaces else "observations"
        self.pi = mlp(space["observations"].shape[0], self.action_space.n, hidden)
        if not self.inference_only:
            self.vf = mlp(space[self.critic_key].shape[0], 1, hidden)

    def _forward(self, batch: dict, **kwargs) -> dict:
        obs = batch[Columns.OBS]
        logits = self.pi(symlog(obs["observations"].float()))
        illegal = obs["action_mask"] == 0
        logits = logits.masked_fill(illegal, torch.finfo(logits.dtype).min)
        return {Columns.ACTION_DIST_INPUTS: logits}

    def compute_values(self, batch: dict, embeddings: Any = None) -> torch.Tensor:
        return self.vf(symlog(batch[Columns.OBS][self.critic_key].float())).squeeze(-1)


def ppo_config(env_config: dict | None = None, *, hidden: int = 64, seed: int = 0,
               batch_size: int = 128, minibatch_size: int = 64, epochs: int = 2,
               lr: float = 3e-4) -> PPOConfig:
    """RLlib's PPO on the env: the env runner and the learner in this process (no extra Ray
    workers), one shared :class:`MaskedActorCritic` for every eVTOL, ``batch_size`` AEC steps
    per iteration. Registers the env (:func:`register`)."""
    module = RLModuleSpec(module_class=MaskedActorCritic, model_config={"hidden": hidden})
    return (
        PPOConfig()
        # RLlib's env check steps a random action of the action space, unmasked; the env
        # raises on an illegal one, so the check fails at random: PettingZoo's api_test
        # (tests/envs/test_api.py) checks the env instead.
        .environment(register(), env_config=dict(env_config or {}), disable_env_checking=True)
        .multi_agent(policies={MODULE_ID}, policy_mapping_fn=_one_module)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={MODULE_ID: module}))
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .learners(num_learners=0)
        .training(train_batch_size_per_learner=batch_size, minibatch_size=minibatch_size,
                  num_epochs=epochs, lr=lr)
        .debugging(seed=seed)
    )


def save_policy(algo_or_module: Any, folder: Any, env: Any) -> Any:
    """Save an algorithm (its checkpoint) or one RLModule (its weights) to ``folder`` with RLlib's
    ``save_to_path``, and beside it what the project's loader checks: the flat columns of the
    vertiport ``env`` (any of its envs) it was trained on
    (:data:`agents.controllers.foreign.METADATA`). The folder."""
    import json
    from pathlib import Path

    from agents.controllers.foreign import METADATA, metadata_for

    folder = Path(folder)
    algo_or_module.save_to_path(folder.resolve().as_posix())
    (folder / METADATA).write_text(json.dumps(metadata_for(env, "flat")))
    return folder


def _one_module(agent_id: str, episode: Any = None, **kwargs: Any) -> str:
    return MODULE_ID
