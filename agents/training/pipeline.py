"""A training run from a train config, stage by stage: the warm start by imitation
(:mod:`~agents.training.imitation`), the ensemble stage (:mod:`~agents.training.ensemble`),
PPO with rsl_rl (:mod:`~agents.training.runner`) and the evaluation against the baselines.

PPO may instead start from a checkpoint (``init_checkpoint``), in place of the warm start.

A run lives in its own folder (``runs/train/<name>/``): the resolved configs, TensorBoard logs,
checkpoints ``model_<it>.pt`` (written atomically), ``curves.csv``, the warm start's
``warmstart.csv`` and progress ``warmstart_state.pt``, ``learning_curves.png`` and the final
evaluation. A resumed run continues from its last checkpoint, or, when it was stopped during the
warm start, after the warm start's last finished round. The command line is
:mod:`agents.training.cli` (``python -m agents.train``, ``make train``).
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path
from typing import Callable

import torch
import yaml

from agents.common.files import write_atomic, write_torch_atomic
from agents.common.seeds import VALIDATION_SEED_BASE
from agents.execution import Backend
from agents.training.callbacks import RunProgress
from agents.training.checkpoints import (WARM_STATE, checkpoint_infos, latest_checkpoint,
                                         ppo_checkpoints)
from agents.training.config import TrainConfig, scenario_configs
from agents.training.curves import WARM_CURVE_KEYS, plot_curves, read_curves, write_curves
from agents.training.ensemble import distil_ensemble
from agents.training.imitation import (load_warm_start_state, padded_sizes,
                                       saved_dagger_rounds, warm_start)
from agents.training.log_writer import CALLBACK_KEY
from agents.training.runner import load_checkpoint_into, make_runner_class, make_vec_env, runner_config
from marl_vertiport.config import ConfigError, build_dataclass, load_config, to_dict, with_rules

Log = Callable[[str], None]


def train(cfg: TrainConfig, run_dir: Path, resume: bool = False, evaluate: bool = True,
          log: Log = print, backend: Backend | None = None, backend_args: list[str] | None = None
          ) -> Path:
    """Train (or resume) in ``run_dir``; returns the final checkpoint's path.

    ``backend`` runs the warm start's and the ensemble's days (default: ``pretrain.workers``
    local processes); ``backend_args`` (such as ``["--backend", "ray"]``) are handed to the
    evaluation at the end. Neither changes the result."""
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
    env_cfg = with_rules(load_config(cfg.env_config), cfg.rules)
    if not resume:
        write_atomic(run_dir / "train_config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
        write_atomic(run_dir / "env_config.yaml", yaml.safe_dump(to_dict(env_cfg), sort_keys=False))
    vec_env = make_vec_env(cfg)
    runner = make_runner_class()(vec_env, runner_config(cfg), log_dir=str(run_dir),
                                 device=cfg.device)
    runner.checkpoint_infos = checkpoint_infos(cfg, env_cfg)
    if resume:
        set_aside_for_more_rounds(run_dir, cfg, log)
    curves = read_curves(run_dir / "curves.csv") if resume else []
    warm_rows = read_curves(run_dir / "warmstart.csv") if resume else []
    ckpt = latest_checkpoint(run_dir) if resume else None
    if resume and ckpt is not None:
        load_checkpoint_into(runner, ckpt)
        runner.current_learning_iteration += 1
        curves = [r for r in curves if r["iteration"] < runner.current_learning_iteration]
        log(f"resuming {run_dir} from {ckpt.name} at iteration {runner.current_learning_iteration}")
    elif cfg.init_checkpoint and not cfg.pretrain.runs:
        warm_rows, curves = [], []
        init_stage(runner, cfg, run_dir, log)
    else:
        if cfg.init_checkpoint:  # the warm start goes on from it (its fits, once resumed)
            load_checkpoint_into(runner, _existing(cfg.init_checkpoint), {"actor": True, "critic": True})
            log(f"the warm start goes on from {cfg.init_checkpoint} (actor and critic weights)")
        warm_rows, curves = warm_start_stage(runner, cfg, env_cfg, run_dir, resume, log, backend), []
    phases = {"set-up and warm start": time.time() - started}
    ppo_started = time.time()
    final = ppo_stage(runner, vec_env, cfg, run_dir, curves, log)
    phases["PPO"] = time.time() - ppo_started
    if curves or warm_rows:
        plot_curves(curves, run_dir / "learning_curves.png", f"GCN-PPO ({cfg.mode}, {cfg.env_config})",
                    warm_rows)
    if evaluate and cfg.evaluation.episodes > 0 and final is not None:
        evaluated = time.time()
        evaluation_stage(final, cfg, run_dir, log, backend_args)
        phases["evaluation"] = time.time() - evaluated
    log("time: " + ", ".join(f"{name} {sec / 60:.1f} min" for name, sec in phases.items())
        + f"; {(time.time() - started) / 60:.1f} min in all")
    return final


def warm_start_stage(runner, cfg: TrainConfig, env_cfg, run_dir: Path, resume: bool, log: Log,
                     backend: Backend | None) -> list[dict[str, float]]:
    """Imitation, then (``ensemble.fits``) the ensemble's distillation and (``warm_start_
    temperature``) the sharpening of the actor PPO starts from; ``model_warmstart.pt``,
    ``model_fit<k>.pt`` (with DAgger: fit 0 is behaviour cloning's, fit k the k-th round's),
    ``model_refit<k>.pt`` and ``model_distilled.pt`` are written on the way. Returns the rows
    of ``warmstart.csv``."""
    # Under torchrun each rank warm-starts on its own seeds; rank 0 writes the curves.
    rank = int(os.environ.get("RANK", "0"))
    state_path = run_dir / (WARM_STATE if rank == 0 else f"warmstart_state_rank{rank}.pt")
    if resume and not state_path.exists():
        raise FileNotFoundError(f"{run_dir}: no checkpoint (model_<iteration>.pt) and no "
                                f"warm-start progress ({state_path.name}) to resume from")
    if not resume:
        state_path.unlink(missing_ok=True)  # a new run starts its warm start over
    warm_rows: list[dict[str, float]] = []

    def on_round(record: dict[str, float]) -> None:
        warm_rows.append(record)
        if rank == 0:
            write_curves(run_dir / "warmstart.csv", warm_rows, WARM_CURVE_KEYS)

    def write_fit(k: int, content: dict) -> None:  # each round's fit as made, to play it paired
        write_torch_atomic(run_dir / f"model_fit{k}.pt", content)

    warm_envs = ([to_dict(c) for c in scenario_configs(cfg)] if cfg.scenarios
                 else to_dict(env_cfg))
    stats = warm_start(runner.alg.actor, cfg, warm_envs, log=log,
                       state_path=state_path, on_round=on_round, backend=backend,
                       on_fit=write_fit if rank == 0 and cfg.pretrain.dagger_rounds else None)
    if not stats:
        return warm_rows
    runner.save(str(run_dir / "model_warmstart.pt"), {"warm_start": stats})
    if cfg.ensemble.fits:
        ens_stats, refits = distil_ensemble(
            runner.alg.actor, cfg, warm_envs, load_warm_start_state(state_path)["data"],
            padded_sizes(warm_envs), log=log, backend=backend)
        if rank == 0:
            for k, content in enumerate(refits, start=1):
                write_torch_atomic(run_dir / f"model_refit{k}.pt", content)
        runner.save(str(run_dir / "model_distilled.pt"), {"warm_start": {**stats, **ens_stats}})
    sharpen_start(runner, cfg, log)
    return warm_rows


def set_aside_for_more_rounds(run_dir: Path, cfg: TrainConfig, log: Log) -> None:
    """Where ``cfg`` asks for more DAgger rounds than the run's warm start was saved with, the
    warm start goes on and PPO starts again from its new result: what PPO and the evaluation
    made from the old one (``model_<it>.pt``, ``curves.csv``, ``eval/``) is moved, not
    deleted, into ``run_dir/after_<k>_rounds/``."""
    state_path = run_dir / WARM_STATE
    if not state_path.exists() or not cfg.pretrain.runs:
        return
    before = saved_dagger_rounds(state_path)
    if before >= cfg.pretrain.dagger_rounds:
        return
    made = ppo_checkpoints(run_dir) + [p for p in (run_dir / "curves.csv", run_dir / "eval")
                                       if p.exists()]
    if not made:
        return
    aside = run_dir / f"after_{before}_rounds"
    if aside.exists():
        raise FileExistsError(f"{aside}: already there; move it away to go on to "
                              f"{cfg.pretrain.dagger_rounds} DAgger rounds")
    aside.mkdir()
    for path in made:
        path.rename(aside / path.name)
    log(f"PPO's outputs from the {before}-round warm start moved to {aside}")


def sharpen_start(runner, cfg: TrainConfig, log: Log) -> None:
    """Divide the logits of the actor PPO starts from by ``warm_start_temperature`` (for good;
    the greedy actions stay), where it is not 1."""
    if cfg.warm_start_temperature != 1.0:
        runner.alg.actor.sharpen(cfg.warm_start_temperature)
        log(f"warm start sharpened: logits / {cfg.warm_start_temperature:g} "
            "(the same greedy actions)")


def init_stage(runner, cfg: TrainConfig, run_dir: Path, log: Log) -> None:
    """PPO starts from ``cfg.init_checkpoint``'s actor and critic (weights only), sharpened by
    ``warm_start_temperature``; the run keeps its starting point as ``model_warmstart.pt``
    (unsharpened, as a warm start's)."""
    path = _existing(cfg.init_checkpoint)
    load_checkpoint_into(runner, path, {"actor": True, "critic": True})
    runner.save(str(run_dir / "model_warmstart.pt"), {"init_checkpoint": str(path)})
    log(f"PPO starts from {path} (actor and critic weights)")
    sharpen_start(runner, cfg, log)


def _existing(init_checkpoint: str) -> Path:
    """``init_checkpoint`` as a path, refused where no file is there."""
    path = Path(init_checkpoint)
    if not path.is_file():
        raise ConfigError(f"init_checkpoint: {path}: no such file")
    return path


def ppo_stage(runner, vec_env, cfg: TrainConfig, run_dir: Path, curves: list[dict[str, float]],
              log: Log) -> Path | None:
    """PPO's iterations up to ``cfg.iterations`` (a critic warm-up first), with the run's
    :class:`~agents.training.callbacks.RunProgress`; returns the final checkpoint."""
    remaining = cfg.iterations - runner.current_learning_iteration
    samples_per_it = cfg.num_envs * cfg.num_steps_per_env
    runner.alg.updates_done = runner.current_learning_iteration
    if runner.alg.actor_frozen:
        log(f"critic warm-up: actor frozen for the first {cfg.critic_warmup_iterations} iterations")
    if remaining > 0:
        runner.cfg[CALLBACK_KEY] = RunProgress(
            runner, vec_env, cfg.iterations, runner.current_learning_iteration, samples_per_it,
            curves, run_dir / "curves.csv", run_dir, log)
        where = ", ".join(cfg.scenarios) if cfg.scenarios else cfg.env_config
        log(f"training {cfg.mode} on {where}: {remaining} iterations of "
            f"{samples_per_it} env steps ({cfg.num_envs} copies x {cfg.num_steps_per_env})")
        # rsl_rl prints a report of every iteration; ours is the progress line of RunProgress.
        with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet):
            runner.learn(remaining)
    vec_env.close()
    return latest_checkpoint(run_dir)


def evaluation_stage(final: Path, cfg: TrainConfig, run_dir: Path, log: Log,
                     backend_args: list[str] | None) -> None:
    """The final checkpoint against ``evaluation.agents`` on validation days (test days stay
    for reported numbers), into ``run_dir/eval``."""
    from agents.evaluate import main as evaluate_main

    first = VALIDATION_SEED_BASE
    seeds = f"{first}:{first + cfg.evaluation.episodes}"
    log(f"evaluating {final.name} against {', '.join(cfg.evaluation.agents)} on validation "
        f"seeds {seeds} (test seeds stay for reported numbers)")
    evaluate_main(["--agents", str(final), *cfg.evaluation.agents, "--seeds", seeds,
                   "--rules", str(cfg.rules), "--out", str(run_dir / "eval"),
                   *(backend_args or [])])
