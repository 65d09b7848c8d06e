"""Warm start of the shared GCN actor by imitation: behaviour cloning of a teacher, then DAgger.

The teachers (``pretrain.teacher``) are those of :mod:`agents.training.teachers`.

Days of demonstrations run as tasks of the execution layer (:mod:`agents.execution`: local
worker processes or a Ray cluster), one day per task, through the Gymnasium env:
the acting eVTOL's observation there is exactly what that eVTOL observes as an AEC agent, so
the same data trains the actor of both training modes. Each round runs ``days`` full days,
``starts`` shorter episodes of a day's first ``start_steps`` steps and ``low_battery_starts``
such episodes with every battery starting low; in the day starts a share ``noise`` of the
driver's actions is replaced by random legal ones (see :func:`round_tasks`). Only steps with a choice
(two or more legal actions) are kept: the others teach nothing. In round 0 the teacher drives;
in each DAgger round the current actor drives (greedily) and the teacher labels the states the
actor visits, and the actor is refit on everything collected so far. A last round of full days
driven by the last fit scores it (with ``pretrain.keep: paired``, every fit drives the same
days); nothing is fit on it, so no teacher runs there.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from tensordict import TensorDict

from agents.common.files import write_torch_atomic
from agents.execution import INTERRUPTED, Backend, LocalBackend
from agents.gcn.features import POLICY_GROUPS
from agents.gcn.padding import pad_observation, to_padded_action
from agents.gcn.padding import to_tensordict as padded_tensordict
from agents.common.seeds import WARM_START_SEED_BASE, training_seed
from agents.training.fit_selection import kept_fit, mean_day_score
from agents.training.teachers import PLANNER_OPTIONS, make_teacher
from marl_vertiport.sim.metrics import TRAINING_METRICS

#: Observation groups the actor reads (the first three are its features, the last its mask).
ACTOR_GROUPS = (*POLICY_GROUPS, "action_mask")


@dataclass(frozen=True)
class DayTask:
    """One day of demonstrations: who drives, who labels."""

    env_config: dict[str, Any]
    seed: int
    steps: int
    teacher: str
    planner_horizon: int
    planner_margin: float = 0.0
    planner_options: dict[str, Any] = dataclasses.field(default_factory=dict)
    """Options of the planner of a planner teacher
    (:data:`~agents.training.teachers.PLANNER_OPTIONS`)."""
    learner: dict[str, Any] | None = None
    """Checkpoint content of the actor that drives (DAgger); ``None``: the teacher drives."""
    noise: float = 0.0
    """Probability that the driver's action at a step with a choice is replaced by a random
    legal one (drawn from a generator seeded by ``seed``); labels are unaffected."""
    labelled: bool = True
    """Whether the teacher labels the decisions; ``False`` (a day that only scores the learner
    that drives it): no teacher runs and no decisions are returned."""


class DemonstrationLog:
    """The demonstrations of a day: the decisions with a choice (two or more legal actions): each observation's
    groups, its label and its weight; as arrays by :meth:`arrays`."""

    def __init__(self) -> None:
        self.rows: dict[str, list[np.ndarray]] = {k: [] for k in ACTOR_GROUPS}
        self.labels: list[int] = []
        self.weights: list[float] = []
        self.first: dict[str, np.ndarray] | None = None

    def see(self, obs: dict) -> None:
        """Note the shapes of a day's observations (so an empty log still has them)."""
        if self.first is None:
            self.first = {**obs["observation"], "action_mask": obs["action_mask"]}

    def add(self, obs: dict, label: int, weight: float) -> None:
        for key in ACTOR_GROUPS[:3]:
            self.rows[key].append(obs["observation"][key])
        self.rows["action_mask"].append(obs["action_mask"])
        self.labels.append(label)
        self.weights.append(weight)

    def arrays(self) -> dict[str, np.ndarray]:
        """``port_nodes (T, P, 4)``, ``evtol_nodes (T, N, 13)``, ``self (T, 11)``,
        ``action_mask (T, A)``, ``label (T,)`` and ``regret (T,)`` of the ``T`` decisions."""
        first = self.first or {}
        data = {k: np.stack(v) if v else np.empty((0, *np.shape(first[k])), np.asarray(first[k]).dtype)
                for k, v in self.rows.items()}
        data["label"] = np.asarray(self.labels, dtype=np.int64)
        data["regret"] = np.asarray(self.weights, dtype=np.float32)
        return data


class Demonstrator:
    """The driver of a demonstration day, as a controller of the episode loop: at a step with a
    choice the teacher labels the state (and the decision is logged with what a wrong choice
    costs, see :func:`label_weights`), then the learner acts if there is one, else the teacher's
    label is taken; in the day starts a share ``noise`` of the actions is replaced by a random
    legal one. A step without a choice takes its one legal action. The teacher is bound to the
    simulator at the start of the day; it keeps the seed it was made with."""

    def __init__(self, teacher: Any, learner: Any, noise: float, noise_rng: np.random.Generator,
                 log: DemonstrationLog) -> None:
        self.teacher, self.learner, self.noise, self.noise_rng = teacher, learner, noise, noise_rng
        self.log = log
        self.label = 0

    def bind(self, sim: Any) -> None:
        if hasattr(self.teacher, "bind"):
            self.teacher.bind(sim)

    def act(self, obs: dict) -> int:
        teacher, log = self.teacher, self.log
        log.see(obs)
        mask = obs["action_mask"]
        choice = int(mask.sum()) > 1
        if not choice:
            self.label = int(np.argmax(mask))
        elif teacher is not None:
            self.label = int(teacher.act(obs))
            q = getattr(teacher, "last_q", None)
            # What a wrong choice here can cost: the spread of the simulated candidates' values,
            # or without bound where the teacher ruled an action out as unsafe.
            if getattr(teacher, "last_forced", False):
                weight = float("inf")
            else:
                weight = max(q.values()) - min(q.values()) if q and len(q) > 1 else 0.0
            log.add(obs, self.label, weight)
        action = self.learner.act(obs) if self.learner is not None and choice else self.label
        if choice and self.noise > 0.0 and self.noise_rng.random() < self.noise:
            action = int(self.noise_rng.choice(np.flatnonzero(mask)))
        return action


def label_day(task: DayTask) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Run one day (:class:`Demonstrator` through the episode loop, the single-agent env);
    return the observations of the steps with a choice, the teacher's label of each (``label``,
    shape ``(T,)``), and the metrics of the day (so far, for a partial day)."""
    from agents.controllers.episode import run_episode
    from agents.controllers.gcn import GCNController
    from marl_vertiport.config import from_dict
    from marl_vertiport.gym_env import VertiportEnv

    torch.set_num_threads(1)
    if not task.labelled and task.learner is None:
        raise ValueError("a day without labels needs a learner to drive it")
    env = VertiportEnv(config=from_dict(task.env_config))
    teacher = (make_teacher(task.teacher, task.planner_horizon, task.planner_margin, task.seed,
                            learner=task.learner, **task.planner_options)
               if task.labelled else None)
    learner = GCNController(task.learner) if task.learner is not None else None
    log = DemonstrationLog()
    driver = Demonstrator(teacher, learner, task.noise, np.random.default_rng([task.seed, 1]), log)
    metrics = run_episode(env, driver, task.seed, max_steps=task.steps)
    env.close()
    if hasattr(teacher, "close"):
        teacher.close()
    return log.arrays(), metrics


def pad_day(data: dict[str, np.ndarray], max_nodes: int, max_evtols: int) -> dict[str, np.ndarray]:
    """A day's decisions padded to ``max_nodes`` vertiport nodes and ``max_evtols`` eVTOLs
    (agents/gcn/padding.py), labels moved to the padded action space."""
    n_nodes = data["port_nodes"].shape[1]
    out = pad_observation({k: data[k] for k in ACTOR_GROUPS}, max_nodes, max_evtols)
    out["label"] = np.asarray(to_padded_action(data["label"], n_nodes, max_nodes), dtype=np.int64)
    out["regret"] = data["regret"]
    return out


def collect(tasks: list[DayTask], backend: Backend | int, log: Callable[[str], None], tag: str,
            sizes: tuple[int, int] | None = None, run_day: Callable = label_day,
            ) -> tuple[dict[str, np.ndarray], list[dict[str, Any]]]:
    """Run ``tasks`` on ``backend`` (:mod:`agents.execution`; an int: that many local worker
    processes, 1 in this process), logging each day; returns their decisions concatenated in
    task order and each task's metrics, the same on any backend. ``sizes``: ``(max_nodes,
    max_evtols)`` to pad every day to (days of different vertiports). ``run_day(task)`` runs
    one task and returns its decisions (with ``label``) and metrics (default :func:`label_day`).

    Raises:
        KeyboardInterrupt: Ctrl-C stopped the round (nothing of it is kept).
        RuntimeError: a day failed, or a worker or node was lost for good.
    """
    if isinstance(backend, int):
        backend = LocalBackend(backend)
    start = time.time()
    results: dict[int, tuple[dict[str, np.ndarray], dict[str, Any]]] = {}

    def report(i: int, result) -> bool:
        results[i] = result
        m = result[1]
        log(f"  {tag}: episode {len(results)}/{len(tasks)} done ({time.time() - start:.0f} s): "
            f"{m.get('steps', 0)} steps, reward {m.get('total_reward', float('nan')):.0f}, "
            f"lost {m.get('stranded_air', 0)} air / {m.get('stranded_ground', 0)} ground, "
            f"{len(result[0]['label'])} decisions")
        return True

    problem = backend.run(run_day, tasks, report)
    if problem == INTERRUPTED:
        raise KeyboardInterrupt
    if problem is not None:
        raise RuntimeError(f"{tag}: {problem}")
    # In task order, not finishing order: the fit's data, and so the run, do not depend on
    # which worker finished first.
    ordered = [results[i] for i in range(len(tasks))]
    days = [r[0] for r in ordered]
    if sizes is not None:
        days = [pad_day(d, *sizes) for d in days]
    data = {k: np.concatenate([d[k] for d in days]) for k in days[0]}
    return data, [r[1] for r in ordered]


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
              soft_targets: torch.Tensor | None = None) -> dict[str, float]:
    """Cross-entropy of the actor's masked softmax on the teacher's labels, each decision
    weighted by :func:`label_weights` (``regret_cap`` 0: all weights 1). ``soft_targets``
    (``(N, A)`` probabilities): the cross-entropy to these instead (distillation), accuracy
    counted against their most likely action."""
    from agents.gcn.distribution import masked_logits

    obs = to_tensordict(data)
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
            logp = torch.log_softmax(masked_logits(actor.logits(batch), batch["action_mask"]), dim=-1)
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


def _with_battery(env_config: dict[str, Any], pct: float) -> dict[str, Any]:
    """``env_config`` with every battery starting at ``pct`` %."""
    return {**env_config, "battery": {**env_config.get("battery", {}), "initial_pct": float(pct)}}


def _learner(actor, env_config: dict[str, Any], cfg) -> dict[str, Any]:
    """The actor's weights as checkpoint content a worker can load (see GCNController)."""
    from agents.gcn.features import feature_names
    from marl_vertiport.config import to_dict

    first = env_config[0] if isinstance(env_config, list) else env_config
    return {"actor_state_dict": {k: v.detach().cpu().clone() for k, v in actor.state_dict().items()},
            "infos": {"marl_vertiport": {"env_config": first, "train_config": to_dict(cfg),
                                         "feature_schema": feature_names("observation")}}}


def round_tasks(cfg, env_config: dict[str, Any] | list[dict[str, Any]], round_: int,
                learner: dict[str, Any] | None, last: bool) -> list[DayTask]:
    """The episodes of warm-start round ``round_`` (``last``: the round that only scores the
    last fit, full days alone). With a list of env configs (scenarios), episode ``d`` of each
    kind runs config ``d mod len(list)``.

    Seeds of their own, in the training range (agents/common/seeds.py), new in every round: ``pretrain.days`` full days, then ``starts`` day starts (the start of a day, all
    batteries full and every vehicle placed at random, is where an imitation's early error
    costs most), then ``low_battery_starts`` day starts with every battery at the levels of
    ``low_battery_pct`` in turn (a fleet that cannot all be charged in time shows the teacher's
    triage, which its own days rarely reach). Random actions (``noise``) go into the day starts
    only: the full days score the fits as they are."""
    pre = cfg.pretrain
    scenarios = env_config if isinstance(env_config, list) else [env_config]
    base = WARM_START_SEED_BASE + cfg.seed * 1000 + round_ * 100
    n_starts = 0 if last else pre.starts
    lengths = [pre.day_steps] * pre.days + [pre.start_steps] * n_starts
    configs = ([scenarios[d % len(scenarios)] for d in range(pre.days)]
               + [scenarios[d % len(scenarios)] for d in range(n_starts)])
    if not last:
        levels = [pre.low_battery_pct[i % len(pre.low_battery_pct)]
                  for i in range(pre.low_battery_starts)]
        lengths += [pre.start_steps] * len(levels)
        configs += [_with_battery(scenarios[i % len(scenarios)], pct) for i, pct in enumerate(levels)]
    options = {k: True for k in PLANNER_OPTIONS if getattr(pre, f"planner_{k}")}
    return [DayTask(conf, training_seed(base + d), steps, pre.teacher, pre.planner_horizon,
                    pre.planner_margin, options, learner, pre.noise if d >= pre.days else 0.0,
                    labelled=not last)
            for d, (conf, steps) in enumerate(zip(configs, lengths))]


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
               backend: Backend | None = None) -> dict[str, float]:
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

    ``backend``: where the days run (default: ``pretrain.workers`` local processes); the
    result does not depend on it."""
    pre = cfg.pretrain
    if pre.days <= 0 or pre.epochs <= 0:
        return {}
    # What the saved progress must have been made with to be continued.
    # (Not the worker count: the data does not depend on it.)
    made_with = {"pretrain": {k: v for k, v in dataclasses.asdict(pre).items() if k != "workers"},
                 "seed": cfg.seed, "env_config": env_config, "model": dataclasses.asdict(cfg.model),
                 "lost_vehicle_penalty": cfg.lost_vehicle_penalty,
                 **({"init_checkpoint": cfg.init_checkpoint} if cfg.init_checkpoint else {})}
    sizes = padded_sizes(env_config)
    # With an init_checkpoint the actor comes in with its weights, and drives the first round.
    start = _learner(actor, env_config, cfg) if cfg.init_checkpoint else None
    state: dict[str, Any] = {"next_round": 0, "data": None, "fits": [], "scores": [], "stats": {},
                             "records": [], "env_steps": 0, "made_with": made_with}
    if state_path is not None and state_path.exists():
        state = load_warm_start_state(state_path)
        if state["made_with"] != made_with:
            raise ValueError(f"{state_path}: the warm start saved there was made with another "
                             f"configuration (pretrain, seed, env or model); delete it to redo "
                             f"the warm start, or resume with the configuration it was made with")
        log(f"warm start: resuming after round {state['next_round'] - 1} from {state_path.name}")
        torch.set_rng_state(state["torch_rng"])
        if state["fits"]:
            actor.load_state_dict(state["fits"][-1]["actor_state_dict"])
        for record in state["records"]:
            if on_round is not None:
                on_round(record)
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
        log(f"{tag}: {pre.days} days and {per_driver - pre.days} day starts of {pre.start_steps} "
            f"steps ({0 if last else pre.low_battery_starts} with low batteries), "
            f"{'the ' + pre.teacher if learner is None else 'the actor'} drives"
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
                                   pre.learning_rate, cfg.seed + round_, log, tag, pre.regret_cap))
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
    paired = state.get("paired_scores")
    best = kept_fit(pre.keep, scores, paired)
    actor.load_state_dict(fits[best]["actor_state_dict"])
    stats.update({f"fit_{k}_score": v for k, v in enumerate(scores)}, chosen_fit=float(best))
    if paired:
        stats.update({f"fit_{k}_paired_score": v for k, v in enumerate(paired)})
    log(f"warm start: keeping fit {best} of {len(fits)} ({pre.keep}: score "
        f"{(paired if pre.keep == 'paired' else scores)[best]:.0f})")
    return stats


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
