"""Training the GCN ATC with rsl_rl's ``OnPolicyRunner`` and ``PPO``.

``python -m agents.train --config default`` (``make train``). A run lives in its own folder
(``runs/train/<name>/``): the resolved configs, TensorBoard logs, checkpoints ``model_<it>.pt``
(written atomically), ``curves.csv``, the warm start's ``warmstart.csv`` and progress
``warmstart_state.pt``, ``learning_curves.png`` and the final evaluation. ``--resume <run
folder>`` continues an interrupted run from its last checkpoint, or, when it was stopped during
the warm start, after the warm start's last finished round.

rsl_rl does the rollouts, PPO updates, logging and checkpoint content; this module only
configures it, optionally warm-starts the actor by imitation of a teacher (the look-ahead
planner or the expert dispatcher; see agents/training/imitation.py), wraps ``save`` to be atomic and
adds a per-iteration hook (progress line, NaN stop, learning curves).
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import pickle
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml

from agents.common.files import write_atomic, write_torch_atomic
from agents.common.provenance import png_metadata, provenance
from agents.execution import Backend, BackendError, add_backend_arguments, backend_from_args
from agents.training.ensemble import distil_ensemble
from agents.training.imitation import (
    ROUND_METRICS, TEACHERS, load_warm_start_state, padded_sizes, warm_start,
)
from agents.common.seeds import VALIDATION_SEED_BASE
from agents.gcn.features import POLICY_GROUPS, STATE_GROUPS, feature_names
from agents.training.log_writer import register_listener, unregister_listener
from agents.training.vec_env import CRITIC_INPUTS, ROW_LAYOUTS
from marl_vertiport.sim.metrics import TRAINING_METRICS
from marl_vertiport.config import (
    ConfigError, build_dataclass, load_config, load_yaml_dataclass, to_dict,
)

TRAIN_CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "train"
CHECKPOINT_FORMAT = 2  # 2: size-agnostic models, the feature schema in the metadata
#: Columns of ``warmstart.csv``: one row per warm-start round (``driver`` 0: the teacher drove,
#: 1: the actor); ``env_steps`` counts demonstration steps so far; the last row's ``kept_round``
#: is the round whose days the fit kept for PPO drove.
WARM_CURVE_KEYS = ("round", "driver", "env_steps", *ROUND_METRICS, "cross_entropy", "accuracy",
                   "kept_round")
WARM_STATE = "warmstart_state.pt"
CURVE_KEYS = ("iteration", "env_steps", "steps_per_s", "mean_reward", "value_loss", "surrogate_loss",
              "entropy", "learning_rate", *TRAINING_METRICS)


# ------------------------------------------------------------------------------ config schema
@dataclass(frozen=True)
class PretrainConfig:
    """Warm start of the actor by imitation (agents/training/imitation.py)."""

    days: int = 0
    """Days of demonstrations per round (0: no warm start)."""
    day_steps: int = 1440
    """Steps of each demonstration day (a full day: 1440)."""
    starts: int = 0
    """Extra episodes per round that cover only the start of a day."""
    start_steps: int = 120
    """Steps of each of those episodes."""
    teacher: str = "rollout"
    """``rollout`` (the look-ahead planner) or ``heuristic`` (the expert dispatcher)."""
    rollout_horizon: int = 40
    """Steps the rollout teacher simulates per candidate action."""
    rollout_margin: float = 3.0
    """Reward by which the rollout teacher's best action must beat the dispatcher's to be the
    label (near-ties keep the dispatcher's choice, which is easier to learn)."""
    workers: int = 2
    """Processes that run demonstration days."""
    epochs: int = 6
    """Passes over the demonstrations after each round."""
    regret_cap: float = 0.0
    """Weights of the imitation loss: 1 + the teacher's value spread over the candidates,
    capped at this (0: every decision weighs 1); see ``imitation.label_weights``."""
    batch_size: int = 1024
    learning_rate: float = 1e-3
    dagger_rounds: int = 0
    """Rounds of DAgger after behaviour cloning: the actor drives, the teacher labels."""
    noise: float = 0.0
    """Probability that the driver's action at a step with a choice of a day start is replaced
    by a uniformly drawn legal action (the label stays the teacher's): the data then covers the
    states just off the driver's path, from which it must recover (noise injection, as in
    DART). The full days, which also score the fits, run without it."""
    low_battery_starts: int = 0
    """Extra day starts per round in which every battery begins low, cycling through
    ``low_battery_pct``: the teacher shows what to do when a charge cannot be had for all."""
    low_battery_pct: tuple[float, ...] = (10.0, 20.0, 30.0, 45.0)
    """Initial battery levels (%) of those starts."""


@dataclass(frozen=True)
class AlgorithmConfig:
    """rsl_rl PPO arguments (same names)."""

    learning_rate: float = 1e-4
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.001
    clip_param: float = 0.1
    num_learning_epochs: int = 4
    num_mini_batches: int = 4
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0
    schedule: str = "adaptive"
    """``adaptive`` (rsl_rl: the rate follows the KL divergence toward ``desired_kl``),
    ``fixed``, or ``linear`` (decays linearly to 0 over the run's iterations)."""
    desired_kl: float = 0.01
    use_clipped_value_loss: bool = True
    """rsl_rl's value clipping: a value may move at most ``clip_param`` (in reward units) from
    its rollout estimate in an update; with returns of hundreds it all but stops the critic."""
    normalize_advantage_per_mini_batch: bool = False


@dataclass(frozen=True)
class ModelConfig:
    hidden: int = 64
    """Width of the GCN layers."""
    hidden_dims: tuple[int, ...] = (128, 64)
    """MLP head (the paper: 128-64)."""


@dataclass(frozen=True)
class EvaluationConfig:
    episodes: int = 20
    """Held-out episodes per case for the evaluation at the end of training (0: none)."""
    agents: tuple[str, ...] = ("random", "fcfs", "heuristic")
    """Baselines evaluated beside the learned policy."""


@dataclass(frozen=True)
class EnsembleConfig:
    """Distillation of an ensemble of imitation fits after the warm start
    (agents/training/ensemble.py)."""

    fits: int = 0
    """Refits of the warm start's demonstrations from fresh weights; with the warm start they
    form the ensemble (0: no ensemble stage)."""
    days: int = 10
    """Full training days the ensemble drives; their states join the demonstrations."""
    epochs: int = 8
    """Passes of the distillation over those states and the demonstrations."""
    batch_size: int = 256
    learning_rate: float = 3e-4


@dataclass(frozen=True)
class TrainConfig:
    mode: str = "multi_agent"
    """``multi_agent`` (AEC, one row per eVTOL, critic on ``state()``) or ``single_agent``."""
    env_config: str = "paper"
    """The env config of the run (the end-of-training evaluation's first case)."""
    scenarios: tuple[str, ...] = ()
    """Env configs to train across (multi-agent mode): PPO's copies and the warm start's days
    cycle through them. Empty: ``env_config`` alone."""
    lost_vehicle_penalty: float = 0.0
    """Subtracted from the reward the learner sees for each vehicle lost in a step (stranded
    in the air or on the ground); the warm start scores its fits the same way. Evaluation
    reports the paper's reward. 0: the paper's reward."""
    num_envs: int = 32
    num_steps_per_env: int = 32
    iterations: int = 250
    save_interval: int = 10
    seed: int = 0
    device: str = "cpu"
    """``cpu`` or ``cuda`` / ``cuda:0`` where a GPU is present."""
    torch_threads: int = 1
    """Intra-op threads; tiny graph batches run fastest on one."""
    team_reward: bool = True
    """Multi-agent mode: every eVTOL's row gets the step's reward (cooperative); False credits
    only the acting eVTOL (per-agent returns, which reward selfish use of the charger)."""
    rows: str = "agents"
    """Multi-agent mode: ``agents`` (a row per env copy and eVTOL; the rows whose eVTOL has no
    turn only "stay") or ``turns`` (a row per copy: the eVTOL whose turn it is); see
    agents/training/vec_env.py."""
    critic: str = "state"
    """Multi-agent mode: ``state`` (the centralised critic reads ``state()``) or
    ``observation`` (each eVTOL's critic reads its own observation, shared weights). The
    single-agent mode's critic always reads the observation."""
    conflict_penalty: float = 0.0
    """Subtracted from the reward the learner sees in a step whose acting eVTOL was in a
    predicted conflict and did not avoid it (the paper's S = -5, counted as a collision);
    evaluation reports the paper's reward. 0: none."""
    reward_scale: float = 1.0
    """The learner's reward (after the penalties) is multiplied by this; metrics and
    evaluation keep the paper's reward."""
    critic_warmup_iterations: int = 0
    """First PPO iterations with the actor frozen, so that the critic fits the warm-started
    policy before its advantages move the actor."""
    warm_start_temperature: float = 1.0
    """Before PPO, the warm-started actor's logits are divided by this for good (its output
    layers scaled, see :meth:`GraphActor.sharpen`): below 1 the policy PPO samples, and so
    improves, comes closer to the greedy policy that is deployed. The greedy actions stay
    those of the warm start. 1: as imitated."""
    pretrain: PretrainConfig = field(default_factory=PretrainConfig)
    ensemble: EnsembleConfig = field(default_factory=EnsembleConfig)
    algorithm: AlgorithmConfig = field(default_factory=AlgorithmConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)

    def __post_init__(self) -> None:
        checks = [
            (self.mode in ("multi_agent", "single_agent"), "mode", "multi_agent or single_agent"),
            (self.num_envs >= 1, "num_envs", "must be >= 1"),
            (self.num_steps_per_env >= 1, "num_steps_per_env", "must be >= 1"),
            (self.iterations >= 1, "iterations", "must be >= 1"),
            (self.save_interval >= 1, "save_interval", "must be >= 1"),
            (self.torch_threads >= 1, "torch_threads", "must be >= 1"),
            (self.algorithm.learning_rate > 0, "algorithm.learning_rate", "must be > 0"),
            (0 <= self.algorithm.gamma <= 1, "algorithm.gamma", "must lie in [0, 1]"),
            (self.algorithm.schedule in ("adaptive", "fixed", "linear"), "algorithm.schedule",
             "adaptive, fixed or linear"),
            (self.rows in ROW_LAYOUTS, "rows", " or ".join(ROW_LAYOUTS)),
            (self.critic in CRITIC_INPUTS, "critic", " or ".join(CRITIC_INPUTS)),
            (self.rows == "agents" or self.team_reward, "rows",
             "turns holds one stream of turns per copy: it needs team_reward: true"),
            (self.reward_scale > 0 and math.isfinite(self.reward_scale), "reward_scale",
             "must be a finite number > 0"),
            (self.conflict_penalty >= 0, "conflict_penalty", "must be >= 0"),
            (self.warm_start_temperature > 0 and math.isfinite(self.warm_start_temperature),
             "warm_start_temperature", "must be a finite number > 0"),
            (self.warm_start_temperature == 1.0
             or (self.pretrain.days > 0 and self.pretrain.epochs > 0), "warm_start_temperature",
             "sharpens the warm start: it needs pretrain.days and pretrain.epochs > 0"),
            (self.ensemble.fits >= 0, "ensemble.fits", "must be >= 0"),
            (self.ensemble.fits == 0 or (self.pretrain.days > 0 and self.pretrain.epochs > 0),
             "ensemble.fits", "refits the warm start: it needs pretrain.days and pretrain.epochs > 0"),
            (self.ensemble.days >= 1 and self.ensemble.epochs >= 1 and self.ensemble.batch_size >= 1,
             "ensemble", "days, epochs and batch_size must be >= 1"),
            (self.ensemble.learning_rate > 0, "ensemble.learning_rate", "must be > 0"),
            (self.pretrain.days >= 0 and self.pretrain.epochs >= 0 and self.pretrain.dagger_rounds >= 0,
             "pretrain", "days, epochs and dagger_rounds must be >= 0"),
            (self.pretrain.day_steps >= 1, "pretrain.day_steps", "must be >= 1"),
            (self.pretrain.starts >= 0 and self.pretrain.start_steps >= 1, "pretrain.starts",
             "starts must be >= 0 and start_steps >= 1"),
            (self.pretrain.teacher in TEACHERS, "pretrain.teacher", f"one of {', '.join(TEACHERS)}"),
            (self.pretrain.rollout_horizon >= 1, "pretrain.rollout_horizon", "must be >= 1"),
            (self.pretrain.workers >= 1, "pretrain.workers", "must be >= 1"),
            (self.pretrain.regret_cap >= 0, "pretrain.regret_cap", "must be >= 0"),
            (self.pretrain.days + self.pretrain.starts + self.pretrain.low_battery_starts <= 100,
             "pretrain", "days + starts + low_battery_starts must be <= 100 (seeds of a round)"),
            (0.0 <= self.pretrain.noise < 1.0, "pretrain.noise", "must lie in [0, 1)"),
            (self.pretrain.low_battery_starts >= 0, "pretrain.low_battery_starts", "must be >= 0"),
            (len(self.pretrain.low_battery_pct) > 0
             and all(0.0 < b <= 100.0 for b in self.pretrain.low_battery_pct),
             "pretrain.low_battery_pct", "a non-empty list of levels in (0, 100]"),
            (self.evaluation.episodes >= 0, "evaluation.episodes", "must be >= 0"),
            (self.lost_vehicle_penalty >= 0, "lost_vehicle_penalty", "must be >= 0"),
            (self.device == "cpu" or self.device.startswith("cuda"), "device", "cpu or cuda[:N]"),
        ]
        for ok, name, msg in checks:
            if not ok:
                raise ConfigError(f"{name}: {msg}")


def load_train_config(config: str | Path) -> TrainConfig:
    """A name in ``configs/train/`` or a YAML path."""
    return load_yaml_dataclass(TrainConfig, config, TRAIN_CONFIG_DIR, "train config")


# ------------------------------------------------------------------------------ rsl_rl wiring
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
        "algorithm": {"class_name": "agents.training.ppo:WarmupPPO", **to_dict(cfg.algorithm),
                      "critic_warmup_updates": cfg.critic_warmup_iterations,
                      "total_updates": cfg.iterations},
        "actor": {"class_name": "agents.gcn.models:GraphActor", "feature_names": feature_names("observation"),
                  "mask_group": "action_mask",
                  "distribution_cfg": {"class_name": "agents.gcn.distribution:MaskedCategorical"}, **model},
        "critic": {"class_name": "agents.gcn.models:GraphCritic",
                   "feature_names": feature_names("state" if centralised_critic else "observation"), **model},
    }


def scenario_configs(cfg: TrainConfig) -> list:
    """The env configs a run trains on (``scenarios``, or ``env_config`` alone), loaded."""
    return [load_config(name) for name in (cfg.scenarios or (cfg.env_config,))]


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


class TrainingDiverged(RuntimeError):
    """A loss or a parameter became NaN or infinite."""


def _make_runner_class():
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


# ------------------------------------------------------------------------------ checkpoints
def checkpoint_infos(cfg: TrainConfig, env_cfg) -> dict[str, Any]:
    """Run metadata stored in every checkpoint: the configs and the actor's feature schema
    (the column names its weights depend on; layout and fleet sizes do not matter)."""
    return {"marl_vertiport": {"format": CHECKPOINT_FORMAT, "mode": cfg.mode,
                               "train_config": to_dict(cfg), "env_config": to_dict(env_cfg),
                               "scenarios": [c.name for c in scenario_configs(cfg)],
                               "feature_schema": feature_names("observation")}}


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The complete checkpoint with the highest iteration in a run folder (temp files ignored)."""
    found = []
    for path in run_dir.glob("model_*.pt"):
        m = re.fullmatch(r"model_(\d+)\.pt", path.name)
        if m:
            found.append((int(m.group(1)), path))
    return max(found)[1] if found else None


# ------------------------------------------------------------------------------ curves
def read_curves(path: Path) -> list[dict[str, float]]:
    if not path.exists():
        return []
    with path.open() as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def write_curves(path: Path, rows: list[dict[str, float]], keys: tuple[str, ...] = CURVE_KEYS) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(keys))
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row.get(k, float("nan")) for k in keys})
    write_atomic(path, buf.getvalue())


def plot_curves(rows: list[dict[str, float]], out: Path, title: str,
                warm_rows: list[dict[str, float]] = ()) -> None:
    """The paper's learning-curve figure: reward and loss, battery, take-offs/landings, delay,
    collisions per episode against environment steps.

    ``warm_rows`` (``warmstart.csv``): the warm start's rounds come first, shaded, at the
    demonstration steps they took; each point is the mean of the round's full days (the
    teacher's round as a star, the round driven by the fit kept for PPO marked by a dotted line)
    and the imitation cross-entropy is on the loss panel's right axis. PPO's iterations follow;
    its days are driven by the sampling policy, not the greedy one the evaluation runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    offset = max((r["env_steps"] for r in warm_rows), default=0.0)
    x = (np.array([r["env_steps"] for r in rows]) + offset) / 1000.0
    xw = np.array([r["env_steps"] for r in warm_rows]) / 1000.0
    by_teacher = np.array([r.get("driver", 1.0) == 0.0 for r in warm_rows], dtype=bool)
    kept = [r["kept_round"] for r in warm_rows if math.isfinite(r.get("kept_round", float("nan")))]
    kept_x = [xw[i] for i, r in enumerate(warm_rows) if kept and r["round"] == kept[-1]]
    panels = [
        ("Total reward per episode", [("total_reward", "total reward")]),
        ("Losses", [("value_loss", "PPO value loss"), ("surrogate_loss", "PPO surrogate loss")]),
        ("Mean battery (%)", [("mean_battery_pct", "mean battery")]),
        ("Good operations per episode", [("good_takeoffs", "take-offs"), ("good_landings", "landings")]),
        ("Mean delay per eVTOL (min)", [("mean_delay_min", "delay")]),
        ("Safety events per episode", [("collisions", "collisions (S = -5)"),
                                       ("separation_losses", "separation losses")]),
        ("Vehicles lost per episode", [("stranded_air", "in the air"),
                                       ("stranded_ground", "on the ground"),
                                       ("stranded", "all")]),
    ]
    fig, axes = plt.subplots(2, 4, figsize=(18, 7.5))
    axes.ravel()[-1].axis("off")
    for ax, (panel_title, series) in zip(axes.ravel(), panels):
        first = panel_title.startswith("Total")
        if warm_rows:
            ax.axvspan(0.0, offset / 1000.0, color="0.9", zorder=0,
                       label="warm start (imitation)" if first else None)
        if kept_x:
            ax.axvline(kept_x[0], color="0.4", linestyle=":",
                       label="days of the fit kept for PPO" if first else None)
        losses = panel_title == "Losses"
        for n, (key, label) in enumerate(series):
            color = f"C{n}"
            if losses:  # PPO's losses only; the imitation loss goes on the right axis
                y = np.array([r.get(key, np.nan) for r in rows], dtype=float)
                ok = np.isfinite(y)
                if ok.any():
                    ax.plot(x[ok], y[ok], marker=".", color=color, label=label)
                continue
            yw = np.array([r.get(key, np.nan) for r in warm_rows], dtype=float)
            y = np.array([r.get(key, np.nan) for r in rows], dtype=float)
            xs, ys = np.concatenate([xw, x]), np.concatenate([yw, y])
            ok = np.isfinite(ys)
            if ok.any():
                ax.plot(xs[ok], ys[ok], marker=".", color=color, label=label)
            teacher = by_teacher & np.isfinite(yw)
            if teacher.any():
                ax.plot(xw[teacher], yw[teacher], marker="*", markersize=12, linestyle="none",
                        color=color, label="teacher's days" if n == 0 else None)
        if losses and warm_rows:
            ce = np.array([r.get("cross_entropy", np.nan) for r in warm_rows], dtype=float)
            ok = np.isfinite(ce)
            if ok.any():
                right = ax.twinx()
                right.plot(xw[ok], ce[ok], marker="s", color="C3", label="imitation cross-entropy")
                right.set_ylabel("imitation cross-entropy", color="C3")
                right.tick_params(axis="y", colors="C3")
                right.set_ylim(bottom=0.0)
                handles, labels = ax.get_legend_handles_labels()
                more = right.get_legend_handles_labels()
                right.legend(handles + more[0], labels + more[1], fontsize=8, loc="center right")
        ax.set_title(panel_title)
        ax.set_xlabel("environment steps (thousands)")
        ax.grid(alpha=0.3)
        if len(ax.get_legend_handles_labels()[0]) > 1 and not (losses and warm_rows):
            ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    tmp = out.with_name(out.stem + ".tmp.png")
    fig.savefig(tmp, dpi=110, metadata=png_metadata(provenance()))
    plt.close(fig)
    os.replace(tmp, out)


# ------------------------------------------------------------------------------ the run
def train(cfg: TrainConfig, run_dir: Path, resume: bool = False, evaluate: bool = True,
          log=print, backend: Backend | None = None, backend_args: list[str] | None = None
          ) -> Path:
    """Train (or resume) in ``run_dir``; returns the final checkpoint's path.

    ``backend`` runs the warm start's days (default: ``pretrain.workers`` local processes);
    ``backend_args`` (such as ``["--backend", "ray"]``) are handed to the evaluation at the
    end. Neither changes the result."""
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    if world_size > 1:
        # Under torchrun each rank takes its own GPU and its own episodes (rsl_rl's multi-GPU
        # path; rank 0 logs and saves).
        rank, local_rank = int(os.environ.get("RANK", "0")), int(os.environ.get("LOCAL_RANK", "0"))
        if cfg.device == "cuda":
            cfg = build_dataclass(TrainConfig, {**to_dict(cfg), "device": f"cuda:{local_rank}"})
        cfg = build_dataclass(TrainConfig, {**to_dict(cfg), "seed": cfg.seed + 1000 * rank})
    started = time.time()
    torch.set_num_threads(cfg.torch_threads)
    torch.manual_seed(cfg.seed)
    if cfg.device.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device: {cfg.device!r} requested but no CUDA device is available")
    run_dir.mkdir(parents=True, exist_ok=True)
    env_cfg = load_config(cfg.env_config)
    if not resume:
        write_atomic(run_dir / "train_config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
        write_atomic(run_dir / "env_config.yaml", yaml.safe_dump(to_dict(env_cfg), sort_keys=False))
    vec_env = make_vec_env(cfg)
    runner_cls = _make_runner_class()
    runner = runner_cls(vec_env, runner_config(cfg), log_dir=str(run_dir), device=cfg.device)
    runner.checkpoint_infos = checkpoint_infos(cfg, env_cfg)
    curves_path = run_dir / "curves.csv"
    warm_path = run_dir / "warmstart.csv"
    curves = read_curves(curves_path) if resume else []
    warm_rows = read_curves(warm_path) if resume else []
    ckpt = latest_checkpoint(run_dir) if resume else None
    if resume and ckpt is not None:
        load_checkpoint_into(runner, ckpt)
        runner.current_learning_iteration += 1
        curves = [r for r in curves if r["iteration"] < runner.current_learning_iteration]
        log(f"resuming {run_dir} from {ckpt.name} at iteration {runner.current_learning_iteration}")
    else:
        # Under torchrun each rank warm-starts on its own seeds; rank 0 writes the curves.
        rank = int(os.environ.get("RANK", "0"))
        state_path = run_dir / (WARM_STATE if rank == 0 else f"warmstart_state_rank{rank}.pt")
        if resume and not state_path.exists():
            raise FileNotFoundError(f"{run_dir}: no checkpoint (model_<iteration>.pt) and no "
                                    f"warm-start progress ({state_path.name}) to resume from")
        if not resume:
            state_path.unlink(missing_ok=True)  # a new run starts its warm start over
        warm_rows, curves = [], []  # PPO starts from iteration 0: rows of a stopped one go

        def on_round(record: dict[str, float]) -> None:
            warm_rows.append(record)
            if rank == 0:
                write_curves(warm_path, warm_rows, WARM_CURVE_KEYS)

        warm_envs = ([to_dict(c) for c in scenario_configs(cfg)] if cfg.scenarios
                     else to_dict(env_cfg))
        stats = warm_start(runner.alg.actor, cfg, warm_envs, log=log,
                           state_path=state_path, on_round=on_round, backend=backend)
        if stats:
            runner.save(str(run_dir / "model_warmstart.pt"), {"warm_start": stats})
            if cfg.ensemble.fits:
                ens_stats, refits = distil_ensemble(
                    runner.alg.actor, cfg, warm_envs, load_warm_start_state(state_path)["data"],
                    padded_sizes(warm_envs), log=log, backend=backend)
                if rank == 0:
                    for k, content in enumerate(refits, start=1):
                        write_torch_atomic(run_dir / f"model_refit{k}.pt", content)
                runner.save(str(run_dir / "model_distilled.pt"), {"warm_start": {**stats, **ens_stats}})
            if cfg.warm_start_temperature != 1.0:
                runner.alg.actor.sharpen(cfg.warm_start_temperature)
                log(f"warm start sharpened: logits / {cfg.warm_start_temperature:g} "
                    "(the same greedy actions)")
    remaining = cfg.iterations - runner.current_learning_iteration
    samples_per_it = cfg.num_envs * cfg.num_steps_per_env
    t0 = time.time()
    phases = {"set-up and warm start": t0 - started}
    start_it = runner.current_learning_iteration

    pending: dict[int, dict[str, float]] = {}
    terminal = sys.stdout  # rsl_rl's own iteration report is silenced below; ours is not

    def say(msg: str) -> None:
        with contextlib.redirect_stdout(terminal):
            log(msg)

    class Progress:
        """The run's listener (agents/training/log_writer.py): divergence check, progress
        line and the row of curves.csv of every iteration."""

        def iteration_updated(self, it: int, scalars: dict[str, float]) -> None:
            bad = [k for k, v in scalars.items() if k.startswith("Loss/") and not math.isfinite(v)]
            params = list(runner.alg.actor.named_parameters()) + list(runner.alg.critic.named_parameters())
            bad_params = [n for n, p in params if not torch.isfinite(p).all()]
            if bad or bad_params:
                raise TrainingDiverged(f"training diverged at iteration {it}: non-finite "
                                       f"{', '.join(bad + bad_params[:3])}; the last good checkpoint "
                                       f"is kept in {run_dir}")
            nan = float("nan")
            row = {"iteration": it, "env_steps": (it + 1) * samples_per_it,
                   "steps_per_s": samples_per_it * (it + 1 - start_it) / max(time.time() - t0, 1e-9),
                   "mean_reward": nan,
                   "value_loss": scalars.get("Loss/value", nan),
                   "surrogate_loss": scalars.get("Loss/surrogate", nan),
                   "entropy": scalars.get("Loss/entropy", nan),
                   "learning_rate": scalars.get("Loss/learning_rate", nan)}
            row.update(vec_env.pop_episode_means())  # the episodes of this iteration
            pending[it] = row
            done = it + 1 - start_it
            eta = (time.time() - t0) / done * (cfg.iterations - it - 1)
            msg = (f"it {it + 1:4d}/{cfg.iterations}  {row['steps_per_s']:6.0f} steps/s  "
                   f"lr {row['learning_rate']:.1e}  value loss {row['value_loss']:8.3f}")
            if math.isfinite(row.get("total_reward", nan)):
                msg += (f"  | day: reward {row['total_reward']:7.1f} battery {row['mean_battery_pct']:4.1f}% "
                        f"good TO/LD {row['good_takeoffs']:4.1f}/{row['good_landings']:4.1f} "
                        f"delay {row['mean_delay_min']:6.1f} coll {row['collisions']:4.1f} "
                        f"lost {row['stranded_air']:3.1f} air/{row['stranded_ground']:3.1f} ground")
            say(f"{msg}  eta {eta / 60:4.1f} min")

        def iteration_done(self, it: int, scalars: dict[str, float]) -> None:
            row = pending.pop(it, None)
            if row is None:
                return
            row["mean_reward"] = scalars.get("Train/mean_reward", float("nan"))
            curves.append(row)
            write_curves(curves_path, curves)

    runner.alg.updates_done = runner.current_learning_iteration
    if runner.alg.actor_frozen:
        log(f"critic warm-up: actor frozen for the first {cfg.critic_warmup_iterations} iterations")
    register_listener(run_dir, Progress())
    if remaining > 0:
        where = ", ".join(cfg.scenarios) if cfg.scenarios else cfg.env_config
        log(f"training {cfg.mode} on {where}: {remaining} iterations of "
            f"{samples_per_it} env steps ({cfg.num_envs} copies x {cfg.num_steps_per_env})")
        try:
            # rsl_rl prints a report of every iteration; ours is the one line of `say`.
            with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet):
                runner.learn(remaining)
        finally:
            unregister_listener(run_dir)
    final = latest_checkpoint(run_dir)
    vec_env.close()
    phases["PPO"] = time.time() - t0
    if curves or warm_rows:
        plot_curves(curves, run_dir / "learning_curves.png", f"GCN-PPO ({cfg.mode}, {cfg.env_config})",
                    warm_rows)
    if evaluate and cfg.evaluation.episodes > 0 and final is not None:
        from agents.evaluate import main as evaluate_main

        first = VALIDATION_SEED_BASE
        seeds = f"{first}:{first + cfg.evaluation.episodes}"
        log(f"evaluating {final.name} against {', '.join(cfg.evaluation.agents)} on validation "
            f"seeds {seeds} (test seeds stay for reported numbers)")
        evaluated = time.time()
        evaluate_main(["--agents", str(final), *cfg.evaluation.agents, "--seeds", seeds,
                       "--out", str(run_dir / "eval"), *(backend_args or [])])
        phases["evaluation"] = time.time() - evaluated
    log("time: " + ", ".join(f"{name} {sec / 60:.1f} min" for name, sec in phases.items())
        + f"; {(time.time() - started) / 60:.1f} min in all")
    return final


def load_checkpoint_into(runner, path: Path) -> None:
    """Load a checkpoint into a runner (tensors and plain data only), with a one-line error
    when it does not fit or is not one."""
    try:
        runner.load(str(path), map_location=runner.device)
    except (RuntimeError, KeyError, EOFError, OSError, pickle.UnpicklingError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"checkpoint {path} cannot be loaded into this run: {first}") from None


def main(argv: list[str] | None = None, prog: str = "python -m agents.train") -> int:
    import argparse

    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default="default", help="name in configs/train/ or a YAML path")
    parser.add_argument("--resume", metavar="RUN_DIR", help="continue the run in this folder")
    parser.add_argument("--run-dir", help="folder of a new run (default runs/train/<config>_<time>)")
    parser.add_argument("--seed", type=int, help="override the config's seed")
    parser.add_argument("--iterations", type=int, help="override the number of PPO iterations")
    parser.add_argument("--device", help="override the device (cpu, cuda, cuda:0)")
    parser.add_argument("--no-eval", action="store_true", help="skip the evaluation at the end")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="processes for the warm start's and the ensemble's days (1: this "
                             "process; with --backend ray, the CPUs of a Ray instance of its "
                             "own); default: the config's pretrain.workers. The checkpoints do "
                             "not depend on it")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    backend = None
    try:
        if args.resume:
            run_dir = Path(args.resume)
            if not (run_dir / "train_config.yaml").is_file():
                raise ConfigError(f"{run_dir}: not a training run (no train_config.yaml)")
            cfg = load_train_config(run_dir / "train_config.yaml")
        else:
            cfg = load_train_config(args.config)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            seed = "" if args.seed is None else f"_seed{args.seed}"
            run_dir = Path(args.run_dir or f"runs/train/{Path(args.config).stem}{seed}_{stamp}")
        overrides = {}
        if args.seed is not None:
            if args.resume:
                raise ConfigError("--seed: a resumed run keeps the seed it was started with")
            overrides["seed"] = args.seed
        if args.iterations is not None:
            overrides["iterations"] = args.iterations
        if args.device is not None:
            overrides["device"] = args.device
        if overrides:
            cfg = build_dataclass(TrainConfig, {**to_dict(cfg), **overrides})
        if args.workers is not None and args.workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {args.workers}")
        backend = backend_from_args(args, args.workers or cfg.pretrain.workers)
        backend_args = ["--backend", args.backend] + (
            ["--ray-address", args.ray_address] if args.ray_address else [])
        final = train(cfg, run_dir, resume=bool(args.resume), evaluate=not args.no_eval,
                      backend=backend, backend_args=backend_args)
    except (ConfigError, FileNotFoundError, ValueError, TrainingDiverged, BackendError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2 if not isinstance(exc, TrainingDiverged) else 3
    finally:
        if backend is not None:
            backend.close()
    print(f"done: {final}")
    return 0
