"""rsl_rl's wiring: the runner's config from a train config (the classes it names, the
observation groups, the algorithm's arguments), the vector env, and the runner itself, whose
checkpoints are written atomically with the run's metadata and read as tensors only."""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import torch

from agents.gcn.features import POLICY_GROUPS, STATE_GROUPS, feature_names
from agents.training.config import TrainConfig, scenario_configs
from marl_vertiport.config import to_dict


def runner_config(cfg: TrainConfig) -> dict[str, Any]:
    """The ``train_cfg`` dict of rsl_rl's ``OnPolicyRunner``."""
    centralised_critic = cfg.mode == "multi_agent" and cfg.critic == "state"
    model = {"hidden": cfg.model.hidden, "hidden_dims": list(cfg.model.hidden_dims)}
    return {
        "num_steps_per_env": cfg.num_steps_per_env,
        "save_interval": cfg.save_interval,
        # Our progress line, curves and divergence check, through rsl_rl's LogWriter extension.
        "logger": {"class_name": "agents.training.log_writer:RunLogWriter"},
        "obs_groups": {"actor": list(POLICY_GROUPS),
                       "critic": list(STATE_GROUPS if centralised_critic else POLICY_GROUPS)},
        "algorithm": {**to_dict(cfg.algorithm),
                      "critic_warmup_updates": cfg.critic_warmup_iterations,
                      "total_updates": cfg.iterations},
        "actor": {"class_name": cfg.model.actor_class, "feature_names": feature_names("observation"),
                  "mask_group": "action_mask",
                  "distribution_cfg": {"class_name": cfg.model.distribution_class}, **model},
        "critic": {"class_name": cfg.model.critic_class,
                   "feature_names": feature_names("state" if centralised_critic else "observation"), **model},
    }


def make_vec_env(cfg: TrainConfig):
    from agents.training.vec_env import MultiAgentVecEnv, SingleAgentVecEnv

    if cfg.mode == "multi_agent":
        return MultiAgentVecEnv(scenario_configs(cfg), num_envs=cfg.num_envs, device=cfg.device,
                                seed=cfg.seed, team_reward=cfg.team_reward,
                                lost_vehicle_penalty=cfg.lost_vehicle_penalty, rows=cfg.rows,
                                critic=cfg.critic, reward_scale=cfg.reward_scale,
                                conflict_penalty=cfg.conflict_penalty)
    return SingleAgentVecEnv(scenario_configs(cfg), num_envs=cfg.num_envs, device=cfg.device, seed=cfg.seed,
                             lost_vehicle_penalty=cfg.lost_vehicle_penalty,
                             reward_scale=cfg.reward_scale, conflict_penalty=cfg.conflict_penalty)


def make_runner_class():
    from rsl_rl.runners import OnPolicyRunner

    class AtomicRunner(OnPolicyRunner):
        """``OnPolicyRunner`` whose checkpoints are written atomically and carry the metadata
        needed to check them against an env."""

        checkpoint_infos: dict[str, Any] = {}

        def save(self, path: str, infos: dict | None = None) -> None:
            tmp = f"{path}.tmp"
            super().save(tmp, {**self.checkpoint_infos, **(infos or {})})
            os.replace(tmp, path)

        def load(self, path: str, load_cfg: dict | None = None, strict: bool = True,
                 map_location: str | None = None) -> dict:
            """``OnPolicyRunner.load`` with ``weights_only=True``: tensors and plain data only,
            so a checkpoint that carries pickled code is refused, never run."""
            loaded = torch.load(path, weights_only=True, map_location=map_location)
            if self.alg.load(loaded, load_cfg, strict):
                self.current_learning_iteration = loaded["iter"]
            return loaded["infos"]

    return AtomicRunner


def load_checkpoint_into(runner, path: Path, parts: dict[str, bool] | None = None) -> None:
    """Load a checkpoint into a runner (tensors and plain data only), with a one-line error
    when it does not fit or is not one. ``parts``: rsl_rl's ``load_cfg`` (which of ``actor``,
    ``critic``, ``optimizer`` and ``iteration`` to read); None: all of them."""
    try:
        runner.load(str(path), load_cfg=parts, map_location=runner.device)
    except (RuntimeError, KeyError, EOFError, OSError, pickle.UnpicklingError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"checkpoint {path} cannot be loaded into this run: {first}") from None
