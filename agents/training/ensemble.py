"""Distillation of an ensemble of imitation fits into the actor (after the warm start).

Fits of the same demonstrations from different initial weights play quite differently (up to
about 300 points a day apart on the same days; experiments/ensemble-warm-start-rules-v0, "Is it
the stage, or the fit?"), so one warm start is one draw from a lottery. This stage averages the lottery out:

1. **Refits.** The warm start's decisions (``warmstart_state.pt``) are fit ``ensemble.fits``
   more times, each from weights drawn afresh with seed ``REFIT_SEED_BASE + k`` and otherwise
   exactly as the warm start was fit (:func:`refit_actor`; the same function as
   ``python -m agents.studies.refit``).
2. **Ensemble days.** The warm-started actor and its refits, as one controller
   (:class:`agents.controllers.gcn.GCNEnsemble`: the legal action of largest mean log-probability),
   drive ``ensemble.days`` full training days (the scenarios in turn; seeds
   ``ENSEMBLE_SEED_BASE + 1000 * seed + d``) as tasks of the execution layer; the states with a
   choice are kept.
3. **Distillation.** On those states and the demonstrations, the actor (the warm start's
   weights) is trained for ``ensemble.epochs`` epochs to match the ensemble's policy, the
   softmax of the members' mean log-probabilities (cross-entropy to soft targets).

Every step is seeded; a run gives the same actor on any backend.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import torch

from agents.common.seeds import ENSEMBLE_SEED_BASE, training_seed
from agents.execution import Backend, LocalBackend
from agents.training.demonstrations import DemonstrationLog, collect
from agents.training.imitation import _learner, fit_actor, to_tensordict

#: Offset of the refits' seeds: refit ``k`` draws its weights and batches with ``REFIT_SEED_BASE + k``.
REFIT_SEED_BASE = 1000


def refit_actor(actor, data: dict[str, np.ndarray], pre, seed: int):
    """A copy of ``actor`` with every layer's weights drawn afresh from ``seed``, then fit on
    ``data`` as the warm start fits (``pre``: the run's ``pretrain`` settings). ``actor`` is
    not changed. Returns the copy and the fit's statistics."""
    fresh = copy.deepcopy(actor).to("cpu")
    torch.manual_seed(seed)
    for module in fresh.modules():
        if module is not fresh and hasattr(module, "reset_parameters"):
            module.reset_parameters()
    stats = fit_actor(fresh, data, pre.epochs, pre.batch_size, pre.learning_rate, seed,
                      lambda _line: None, f"refit {seed}", pre.regret_cap)
    return fresh, stats


@dataclass(frozen=True)
class EnsembleDay:
    """One full day driven by an ensemble (checkpoint contents of its members)."""

    env_config: dict[str, Any]
    seed: int
    steps: int
    members: tuple[dict[str, Any], ...]


class EnsembleDriver:
    """The ensemble as a controller of the episode loop: at a step with a choice it acts and
    the state is logged with its action as the label; a step without one takes its one legal
    action."""

    def __init__(self, ensemble: Any, log: DemonstrationLog) -> None:
        self.ensemble, self.log = ensemble, log

    def act(self, obs: dict) -> int:
        self.log.see(obs)
        mask = obs["action_mask"]
        if int(mask.sum()) > 1:
            action = self.ensemble.act(obs)
            self.log.add(obs, action, 0.0)
            return action
        return int(np.argmax(mask))


def drive_day(task: EnsembleDay) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Run one day with the ensemble (through the episode loop, the single-agent env); return
    the observations of the steps with a choice (the ensemble's action as ``label``, shape
    ``(T,)``) and the day's metrics."""
    from agents.controllers.episode import run_episode
    from agents.controllers.gcn import GCNEnsemble
    from marl_vertiport.config import from_dict
    from marl_vertiport.gym_env import VertiportEnv

    torch.set_num_threads(1)
    env = VertiportEnv(config=from_dict(task.env_config))
    log = DemonstrationLog()
    metrics = run_episode(env, EnsembleDriver(GCNEnsemble(list(task.members)), log), task.seed,
                          max_steps=task.steps)
    env.close()
    return log.arrays(), metrics


def ensemble_targets(members: list, obs) -> torch.Tensor:
    """``(N, A)`` the ensemble's policy on a batch: the softmax of the members' mean masked
    log-probabilities (:func:`agents.controllers.gcn.mean_log_probabilities`; their normalised
    geometric mean), 0 on illegal actions."""
    from agents.controllers.gcn import mean_log_probabilities

    mask = obs["action_mask"].bool()
    logp = mean_log_probabilities(members, obs)
    return torch.softmax(logp.masked_fill(~mask, torch.finfo(logp.dtype).min), dim=-1)


def distil(student, members: list, data: dict[str, np.ndarray], epochs: int, batch_size: int,
           learning_rate: float, seed: int, log: Callable[[str], None]) -> dict[str, float]:
    """Train ``student`` to match the ensemble's policy (:func:`ensemble_targets`) on ``data``:
    :func:`~agents.training.imitation.fit_actor` with the ensemble's probabilities as soft
    targets (every decision weighing 1)."""
    target = ensemble_targets(members, to_tensordict(data))
    plain = {**data, "regret": np.zeros(len(target), dtype=np.float32)}
    stats = fit_actor(student, plain, epochs, batch_size, learning_rate, seed, log,
                      "distillation", soft_targets=target)
    return {"distill_cross_entropy": stats["cross_entropy"],
            "distill_agreement": stats["accuracy"], "distill_samples": stats["samples"]}


def distil_ensemble(actor, cfg, env_config: dict[str, Any] | list[dict[str, Any]],
                    data: dict[str, np.ndarray], sizes: tuple[int, int] | None,
                    log: Callable[[str], None] = print,
                    backend: Backend | None = None) -> tuple[dict[str, float], list[dict[str, Any]]]:
    """The stage of the module docstring on the warm-started ``actor`` (changed in place) and
    the warm start's decisions ``data``; ``cfg`` is the run's ``TrainConfig``, ``sizes`` the
    ``(max_nodes, max_evtols)`` the days are padded to (several scenarios). Returns the
    statistics and the refits' checkpoint contents.

    Raises:
        KeyboardInterrupt: Ctrl-C stopped the ensemble days.
        RuntimeError: a day failed, or a worker or node was lost for good.
    """
    ens, pre = cfg.ensemble, cfg.pretrain
    device = next(actor.parameters()).device
    actor.to("cpu")
    members = [actor]
    for k in range(1, ens.fits + 1):
        start = time.time()
        fresh, stats = refit_actor(actor, data, pre, REFIT_SEED_BASE + k)
        members.append(fresh)
        log(f"ensemble: refit {k}/{ens.fits} of the demonstrations from fresh weights "
            f"({time.time() - start:.0f} s): cross-entropy {stats['cross_entropy']:.3f}, "
            f"teacher-action accuracy {stats['accuracy']:.1%}")
    contents = tuple(_learner(m, env_config, cfg) for m in members)
    scenarios = env_config if isinstance(env_config, list) else [env_config]
    base = ENSEMBLE_SEED_BASE + 1000 * cfg.seed
    tasks = [EnsembleDay(scenarios[d % len(scenarios)], training_seed(base + d), pre.day_steps,
                         contents) for d in range(ens.days)]
    backend = backend or LocalBackend(pre.workers)
    log(f"ensemble: the warm start and its {ens.fits} refits drive {ens.days} days "
        f"({backend.describe()})")
    new, metrics = collect(tasks, backend, log, "ensemble days", sizes, run_day=drive_day)
    both = {k: np.concatenate([data[k], new[k]]) for k in data}
    rewards = [m["total_reward"] for m in metrics]
    log(f"ensemble: distilling into the actor ({len(data['label'])} demonstration and "
        f"{len(both['label']) - len(data['label'])} ensemble-day decisions)")
    stats = distil(actor, members, both, ens.epochs, ens.batch_size, ens.learning_rate,
                   cfg.seed, log)
    actor.to(device)
    stats["ensemble_day_reward"] = float(np.mean(rewards))
    return stats, list(contents[1:])
