"""Warm start of the shared GCN actor by imitation: behaviour cloning of a teacher, then DAgger.

The teachers (``pretrain.teacher``) are those of :mod:`agents.training.teachers`; the days they
label, and who drives them, are those of :mod:`agents.training.demonstrations`. In round 0 the
teacher drives (or the ``init_checkpoint``'s actor); in each DAgger round the current actor
drives (greedily) and the teacher labels the states the actor visits, and the actor is refit on
everything collected so far. A last round of full days driven by the last fit scores it (with
``pretrain.keep: paired``, every fit drives the same days); nothing is fit on it, so no teacher
runs there.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from tensordict import TensorDict

from agents.common.files import write_torch_atomic
from agents.execution import Backend, LocalBackend
from agents.gcn.padding import to_tensordict as padded_tensordict
from agents.training.demonstrations import ACTOR_GROUPS, collect, round_tasks
from agents.training.fit_selection import kept_fit, mean_day_score
from marl_vertiport.sim.metrics import TRAINING_METRICS


def to_tensordict(data: dict[str, np.ndarray]) -> TensorDict:
    """Collected arrays as the actor's observation groups, rows first (the shared converter,
    :func:`agents.gcn.padding.to_tensordict`)."""
    groups = [*ACTOR_GROUPS, *(k for k in ("port_valid", "evtol_valid") if k in data)]
    return padded_tensordict({k: data[k] for k in groups}, len(data["label"]))


def label_weights(regret: np.ndarray, cap: float) -> np.ndarray:
    """Per-decision weights of the imitation loss: ``1 + min(regret, cap)``, where ``regret`` is
    the spread of the teacher's simulated values over the candidates (0 where it simulated
    none, infinite where it ruled a legal action out as unsafe). Decisions whose wrong choice
    costs much (a vehicle left to drain, a take-off out of its window) count more than
    near-ties (cost-sensitive imitation, as in AggreVaTe)."""
    return 1.0 + np.minimum(regret, cap)


def fit_actor(actor, data: dict[str, np.ndarray], epochs: int, batch_size: int, learning_rate: float,
              seed: int, log: Callable[[str], None], tag: str, regret_cap: float = 0.0,
              soft_targets: torch.Tensor | None = None, rule_weight: float = 0.0) -> dict[str, float]:
    """Cross-entropy of the actor's masked softmax on the teacher's labels, each decision
    weighted by :func:`label_weights` (``regret_cap`` 0: all weights 1). ``soft_targets``
    (``(N, A)`` probabilities): the cross-entropy to these instead (distillation), accuracy
    counted against their most likely action. ``rule_weight`` > 0: the softmax is that of the
    logits plus ``rule_weight`` on the rule's choice (``data["rule"]``), the policy that
    :class:`~agents.controllers.prior.RulePriorController` plays, so the actor learns where to
    depart from the rule."""
    from agents.gcn.distribution import masked_logits

    obs = to_tensordict(data)
    bonus = None
    if rule_weight > 0:
        if "rule" not in data:
            raise ValueError("rule_weight needs the rule's choice of every decision (data['rule'])")
        bonus = rule_weight * torch.nn.functional.one_hot(
            torch.from_numpy(data["rule"]), obs["action_mask"].shape[-1]).float()
    target = (torch.from_numpy(data["label"]) if soft_targets is None
              else soft_targets.argmax(-1))
    weight = torch.from_numpy(label_weights(data["regret"], regret_cap)).float()
    opt = torch.optim.Adam(actor.parameters(), lr=learning_rate)
    gen = torch.Generator().manual_seed(seed)
    n = len(target)
    stats: dict[str, float] = {}
    actor.train()
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=gen)
        ce_sum = acc_sum = 0.0
        for i in range(0, n, batch_size):
            idx = perm[i:i + batch_size]
            batch = obs[idx]
            logits = masked_logits(actor.logits(batch), batch["action_mask"])
            if bonus is not None:
                logits = logits + bonus[idx]
            logp = torch.log_softmax(logits, dim=-1)
            w = weight[idx]
            if soft_targets is None:
                ce = -(logp.gather(-1, target[idx].unsqueeze(-1)).squeeze(-1) * w).sum() / w.sum()
            else:
                ce = -((soft_targets[idx] * logp).sum(-1) * w).sum() / w.sum()
            opt.zero_grad()
            ce.backward()
            torch.nn.utils.clip_grad_norm_(actor.parameters(), 1.0)
            opt.step()
            ce_sum += float(ce.detach()) * len(idx)  # weighted cross-entropy, per decision
            acc_sum += float((logp.argmax(-1) == target[idx]).float().sum())
        stats = {"cross_entropy": ce_sum / n, "accuracy": acc_sum / n, "samples": float(n)}
        log(f"  {tag} epoch {epoch + 1}/{epochs}: cross-entropy {stats['cross_entropy']:.3f}, "
            f"teacher-action accuracy {stats['accuracy']:.1%} on {n} decisions")
    return stats


def _learner(actor, env_config: dict[str, Any], cfg) -> dict[str, Any]:
    """The actor's weights as checkpoint content a worker can load (see GCNController)."""
    from agents.gcn.features import feature_names
    from marl_vertiport.config import to_dict

    first = env_config[0] if isinstance(env_config, list) else env_config
    return {"actor_state_dict": {k: v.detach().cpu().clone() for k, v in actor.state_dict().items()},
            "infos": {"marl_vertiport": {"env_config": first, "train_config": to_dict(cfg),
                                         "feature_schema": feature_names("observation")}}}


#: Day metrics averaged per warm-start round for the learning curve (``warmstart.csv``).
ROUND_METRICS = TRAINING_METRICS


def padded_sizes(env_config: dict[str, Any] | list[dict[str, Any]]) -> tuple[int, int] | None:
    """``(max_nodes, max_evtols)`` over a list of env configs (the size days of several
    vertiports are padded to); ``None`` for a single config (no padding)."""
    if not isinstance(env_config, list):
        return None
    from marl_vertiport.config import from_dict
    from marl_vertiport.sim.layout import Layout

    built = [from_dict(c) for c in env_config]
    return max(Layout.from_config(c).n_nodes for c in built), max(c.fleet_size for c in built)


def warm_start(actor, cfg, env_config: dict[str, Any] | list[dict[str, Any]],
               log: Callable[[str], None] = print,
               state_path: Path | None = None,
               on_round: Callable[[dict[str, float]], None] | None = None,
               backend: Backend | None = None,
               on_fit: Callable[[int, dict[str, Any]], None] | None = None) -> dict[str, float]:
    """Behaviour cloning then ``pretrain.dagger_rounds`` rounds of DAgger (see the module
    docstring); ``cfg`` is the :class:`~agents.training.config.TrainConfig`.

    ``env_config``: the env config, or a list of them (scenarios; days are padded to the
    largest vertiport and fleet of the list).

    Each fit's actor is scored by the mean :func:`day_score` of the full days it drives in the
    next round (the last one by a round of days of its own, not fit on); the actor keeps the weights of
    the best-scoring fit, as DAgger prescribes (it returns the best of its iterates, not
    necessarily the last). Returns the last fit's statistics, the teacher's mean reward on the
    days it drives, each fit's score and the fit kept.

    ``state_path``: after every round, everything needed to go on (the decisions collected,
    the fits, the scores, torch's random state) is written there atomically; a call that finds
    the file continues after its last round and gives the same result as a run never
    interrupted. ``on_round(record)`` receives, per round, the mean metrics of its full days
    (:data:`ROUND_METRICS`), who drove, the demonstration steps so far and the fit's loss; the
    last round's record also names the round driven by the fit that is kept (``kept_round``).
    ``on_fit(k, content)`` receives fit ``k``'s checkpoint content as soon as it is made (on
    resume, the fits made before first), so a long loop can be played round by round.

    ``backend``: where the days run (default: ``pretrain.workers`` local processes); the
    result does not depend on it."""
    pre = cfg.pretrain
    if not pre.runs:
        return {}
    # What the saved progress must have been made with to be continued.
    # (Not the worker count: the data does not depend on it.)
    # (Nor options at the defaults they were added with: states saved before them go on.)
    added = {"rule_weight": 0.0, "propose_with_prior": True}
    made_with = {"pretrain": {k: v for k, v in dataclasses.asdict(pre).items()
                              if k != "workers" and (k not in added or v != added[k])},
                 "seed": cfg.seed, "env_config": env_config, "model": dataclasses.asdict(cfg.model),
                 "lost_vehicle_penalty": cfg.lost_vehicle_penalty,
                 **({"init_checkpoint": cfg.init_checkpoint} if cfg.init_checkpoint else {})}
    sizes = padded_sizes(env_config)
    # With an init_checkpoint the actor comes in with its weights, and drives the first round.
    start = _learner(actor, env_config, cfg) if cfg.init_checkpoint else None
    state: dict[str, Any] = {"next_round": 0, "data": None, "fits": [], "scores": [], "stats": {},
                             "records": [], "env_steps": 0, "made_with": made_with}
    if state_path is not None and state_path.exists():
        state = _continued(load_warm_start_state(state_path), made_with, state_path, log)
        log(f"warm start: resuming after round {state['next_round'] - 1} from {state_path.name}")
        torch.set_rng_state(state["torch_rng"])
        if state["fits"]:
            actor.load_state_dict(state["fits"][-1]["actor_state_dict"])
        for record in state["records"]:
            if on_round is not None:
                on_round(record)
        for k, fit in enumerate(state["fits"]):
            if on_fit is not None:
                on_fit(k, fit)
    stats, fits, scores = state["stats"], state["fits"], state["scores"]
    backend = backend or LocalBackend(pre.workers)
    where = backend.describe()
    for round_ in range(state["next_round"], pre.dagger_rounds + 2):
        last = round_ == pre.dagger_rounds + 1  # scores the last fit; nothing is refit
        learner = fits[-1] if fits else start
        drivers = fits if last and pre.keep == "paired" else [learner]
        tasks = [t for d in drivers for t in round_tasks(cfg, env_config, round_, d, last)]
        tag = ("scoring the last fit" if len(drivers) == 1 and last else
               f"scoring the {len(drivers)} fits on the same days" if last else
               "demonstrations" if round_ == 0 else f"DAgger round {round_}")
        per_driver = len(tasks) // len(drivers)
        prior = (f" with the dispatcher as its prior (weight {pre.rule_weight:g})"
                 + ("" if pre.propose_with_prior else ", proposing to the teacher alone")
                 if learner is not None and pre.rule_weight else "")
        log(f"{tag}: {pre.days} days and {per_driver - pre.days} day starts of {pre.start_steps} "
            f"steps ({0 if last else pre.low_battery_starts} with low batteries), "
            f"{'the ' + pre.teacher if learner is None else 'the actor'} drives{prior}"
            f"{f' ({pre.noise:.0%} random actions in the starts)' if pre.noise and not last else ''}, "
            f"{'no labels' if last else f'the {pre.teacher} teacher labels'} "
            f"({where})")
        started = time.monotonic()
        new, metrics = collect(tasks, backend, log, tag, sizes)
        collected = time.monotonic()
        if last and pre.keep == "paired":  # each fit's score on the days every fit drove
            state["paired_scores"] = [
                mean_day_score(metrics[k * per_driver:(k + 1) * per_driver], pre.day_steps,
                               cfg.lost_vehicle_penalty) for k in range(len(drivers))]
            log("  fits scored on the same days: " + ", ".join(
                f"fit {k} {v:.0f}" for k, v in enumerate(state["paired_scores"])))
        metrics = metrics[-per_driver:]  # the last fit's days make the round's record
        full = [m for m in metrics if m["steps"] == pre.day_steps]
        score = mean_day_score(metrics, pre.day_steps, cfg.lost_vehicle_penalty)
        if learner is None:
            stats["teacher_reward"] = score
        elif learner is start:
            stats["start_score"] = score
            log(f"  the starting policy scores {score:.0f} (mean reward of its days, less "
                f"{cfg.lost_vehicle_penalty:g} per vehicle lost)")
        else:
            scores.append(score)
            log(f"  fit {len(scores) - 1} scores {scores[-1]:.0f} (mean reward of its days, "
                f"less {cfg.lost_vehicle_penalty:g} per vehicle lost)")
        state["env_steps"] += int(sum(m["steps"] for m in metrics))
        record = {"round": float(round_), "driver": 0.0 if learner is None else 1.0,
                  "env_steps": float(state["env_steps"]),
                  **{k: float(np.mean([m[k] for m in full])) if full else float("nan")
                     for k in ROUND_METRICS}}
        if last:  # the fit kept for PPO: the round it drove in after its fit
            kept = kept_fit(pre.keep, scores, state.get("paired_scores"))
            record["kept_round"] = float(kept + 1)
        else:
            state["data"] = new if state["data"] is None else {
                k: np.concatenate([state["data"][k], new[k]]) for k in state["data"]}
            actor_device = next(actor.parameters()).device
            actor.to("cpu")
            epochs = pre.dagger_epochs if round_ and pre.dagger_epochs else pre.epochs
            stats.update(fit_actor(actor, state["data"], epochs, pre.batch_size,
                                   pre.learning_rate, cfg.seed + round_, log, tag, pre.regret_cap,
                                   rule_weight=pre.rule_weight))
            actor.to(actor_device)
            fits.append(_learner(actor, env_config, cfg))
            record.update(cross_entropy=stats["cross_entropy"], accuracy=stats["accuracy"])
        log(f"  {tag}: days {collected - started:.0f} s"
            + ("" if last else f", fit {time.monotonic() - collected:.0f} s"))
        state["records"].append(record)
        state["next_round"] = round_ + 1
        if state_path is not None:
            save_warm_start_state(state_path, state)
        if on_round is not None:
            on_round(record)
        if on_fit is not None and not last:
            on_fit(len(fits) - 1, fits[-1])
    paired = state.get("paired_scores")
    best = kept_fit(pre.keep, scores, paired)
    actor.load_state_dict(fits[best]["actor_state_dict"])
    stats.update({f"fit_{k}_score": v for k, v in enumerate(scores)}, chosen_fit=float(best))
    if paired:
        stats.update({f"fit_{k}_paired_score": v for k, v in enumerate(paired)})
    log(f"warm start: keeping fit {best} of {len(fits)} ({pre.keep}: score "
        f"{(paired if pre.keep == 'paired' else scores)[best]:.0f})")
    return stats


def _continued(state: dict[str, Any], made_with: dict[str, Any], path: Path,
               log: Callable[[str], None]) -> dict[str, Any]:
    """The saved progress ``state``, checked against this run's ``made_with``. Progress saved
    with fewer ``dagger_rounds`` and otherwise the same configuration goes on to more rounds: the
    round that only scored the last fit, if it ran, is dropped and replaced by a DAgger round,
    so the result is that of a run made with the new count from the start. Anything else that
    differs raises ``ValueError`` naming ``path``."""
    saved = state["made_with"]
    if saved == made_with:
        return state
    before = saved.get("pretrain", {}).get("dagger_rounds")
    rounds = made_with["pretrain"]["dagger_rounds"]
    if (not isinstance(before, int)
            or {**saved, "pretrain": {**saved["pretrain"], "dagger_rounds": rounds}} != made_with):
        raise ValueError(f"{path}: the warm start saved there was made with another "
                         f"configuration (pretrain, seed, env or model); delete it to redo "
                         f"the warm start, or resume with the configuration it was made with")
    if rounds < before:
        raise ValueError(f"{path}: the warm start saved there has {before} DAgger rounds; it can "
                         f"go on to more rounds, not fewer (pretrain.dagger_rounds: {rounds})")
    if state["next_round"] == before + 2:  # the scoring round ran: a DAgger round takes its place
        state["records"].pop()
        state["scores"].pop()
        state.pop("paired_scores", None)
        state["env_steps"] = int(state["records"][-1]["env_steps"])
        state["next_round"] = before + 1
    log(f"warm start: going on from {before} to {rounds} DAgger rounds")
    return {**state, "made_with": made_with}


def saved_dagger_rounds(path: Path) -> int:
    """The ``pretrain.dagger_rounds`` the warm-start progress at ``path`` was made with."""
    return int(load_warm_start_state(path)["made_with"]["pretrain"]["dagger_rounds"])


def save_warm_start_state(path: Path, state: dict[str, Any]) -> None:
    """Write the warm start's progress atomically (see :func:`warm_start`), as tensors and
    plain data only, so that :func:`load_warm_start_state` reads it without unpickling code."""
    data = state.get("data")
    if isinstance(data, dict):
        data = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in data.items()}
    write_torch_atomic(path, {**state, "data": data, "torch_rng": torch.get_rng_state()})


def load_warm_start_state(path: Path) -> dict[str, Any]:
    """Read a warm start's progress; a file that is not one raises ``ValueError`` naming it.

    Loaded with ``weights_only=True``: tensors and plain data only, so a file that carries
    pickled code is refused and the code is never run."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated, foreign, or carrying more than tensors and plain data
        raise ValueError(f"{path}: not a readable warm-start state ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''}); files are loaded as "
                         f"tensors and plain data only; delete it to redo the warm start") from None
    if isinstance(state, dict) and isinstance(state.get("data"), dict):
        state["data"] = {k: v.numpy() for k, v in state["data"].items()}
    missing = {"next_round", "data", "fits", "scores", "stats", "records", "env_steps",
               "made_with", "torch_rng"} - set(state if isinstance(state, dict) else ())
    if missing:
        raise ValueError(f"{path}: not a warm-start state (missing {', '.join(sorted(missing))}); "
                         f"delete it to redo the warm start")
    return state
