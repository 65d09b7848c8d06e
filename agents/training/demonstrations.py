"""Demonstration days of the warm start (:mod:`agents.training.imitation`): who drives, who
labels, what is kept, and the episodes of each round.

Days of demonstrations run as tasks of the execution layer (:mod:`agents.execution`: local
worker processes or a Ray cluster), one day per task, through the Gymnasium env:
the acting eVTOL's observation there is exactly what that eVTOL observes as an AEC agent, so
the same data trains the actor of both training modes. Each round runs ``days`` full days,
``starts`` shorter episodes of a day's first ``start_steps`` steps and ``low_battery_starts``
such episodes with every battery starting low; in the day starts a share ``noise`` of the
driver's actions is replaced by random legal ones (see :func:`round_tasks`). Only steps with a
choice (two or more legal actions) are kept: the others teach nothing. With
``pretrain.rule_weight`` the dispatcher's choice at each of them is kept too (``rule``), the
prior the actor is fit against, and the actor drives with it (:mod:`agents.controllers.prior`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import torch

from agents.common.seeds import WARM_START_SEED_BASE, training_seed
from agents.execution import INTERRUPTED, Backend, LocalBackend
from agents.gcn.features import POLICY_GROUPS
from agents.gcn.padding import pad_observation, to_padded_action
from agents.training.teachers import PLANNER_OPTIONS, make_teacher


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
    rule_weight: float = 0.0
    """The dispatcher as the learner's prior (``pretrain.rule_weight``): the learner drives,
    and proposes to a ``lookahead`` teacher, as ``prior[weight=rule_weight]``, and each decision
    keeps the dispatcher's choice (``rule``). 0: the learner alone, no ``rule`` kept."""
    propose_with_prior: bool = True
    """With ``rule_weight`` > 0: whether the learner proposes to the teacher with its prior
    (``False``: the learner alone proposes, while it drives with the prior)."""


class DemonstrationLog:
    """The demonstrations of a day: the decisions with a choice (two or more legal actions): each observation's
    groups, its label and its weight; as arrays by :meth:`arrays`."""

    def __init__(self, with_rule: bool = False) -> None:
        self.rows: dict[str, list[np.ndarray]] = {k: [] for k in ACTOR_GROUPS}
        self.labels: list[int] = []
        self.weights: list[float] = []
        #: The rule's choice at each decision (kept only ``with_rule``).
        self.rules: list[int] | None = [] if with_rule else None
        self.first: dict[str, np.ndarray] | None = None

    def see(self, obs: dict) -> None:
        """Note the shapes of a day's observations (so an empty log still has them)."""
        if self.first is None:
            self.first = {**obs["observation"], "action_mask": obs["action_mask"]}

    def add(self, obs: dict, label: int, weight: float, rule: int | None = None) -> None:
        for key in ACTOR_GROUPS[:3]:
            self.rows[key].append(obs["observation"][key])
        self.rows["action_mask"].append(obs["action_mask"])
        self.labels.append(label)
        self.weights.append(weight)
        if self.rules is not None:
            if rule is None:
                raise ValueError("this log keeps the rule's choice of every decision: give it")
            self.rules.append(rule)

    def arrays(self) -> dict[str, np.ndarray]:
        """``port_nodes (T, P, 4)``, ``evtol_nodes (T, N, 13)``, ``self (T, 11)``,
        ``action_mask (T, A)``, ``label (T,)`` and ``regret (T,)`` of the ``T`` decisions, and
        ``rule (T,)`` for a log kept ``with_rule``."""
        first = self.first or {}
        data = {k: np.stack(v) if v else np.empty((0, *np.shape(first[k])), np.asarray(first[k]).dtype)
                for k, v in self.rows.items()}
        data["label"] = np.asarray(self.labels, dtype=np.int64)
        data["regret"] = np.asarray(self.weights, dtype=np.float32)
        if self.rules is not None:
            data["rule"] = np.asarray(self.rules, dtype=np.int64)
        return data


class Demonstrator:
    """The driver of a demonstration day, as a controller of the episode loop: at a step with a
    choice the teacher labels the state (and the decision is logged with what a wrong choice
    costs, see :func:`~agents.training.imitation.label_weights`), then the learner acts if
    there is one, else the teacher's label is taken; in the day starts a share ``noise`` of the
    actions is replaced by a random legal one. A step without a choice takes its one legal
    action. With a ``rule`` (a controller), its choice at each decision is logged too. The
    teacher, the learner and the rule are bound to the simulator at the start of the day; each
    keeps the seed it was made with."""

    def __init__(self, teacher: Any, learner: Any, noise: float, noise_rng: np.random.Generator,
                 log: DemonstrationLog, rule: Any = None) -> None:
        self.teacher, self.learner, self.noise, self.noise_rng = teacher, learner, noise, noise_rng
        self.log, self.rule = log, rule
        self.label = 0

    def bind(self, sim: Any) -> None:
        for part in (self.teacher, self.learner, self.rule):
            if hasattr(part, "bind"):
                part.bind(sim)

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
            log.add(obs, self.label, weight,
                    None if self.rule is None else int(self.rule.act(obs)))
        action = self.learner.act(obs) if self.learner is not None and choice else self.label
        if choice and self.noise > 0.0 and self.noise_rng.random() < self.noise:
            action = int(self.noise_rng.choice(np.flatnonzero(mask)))
        return action


def label_day(task: DayTask) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Run one day (:class:`Demonstrator` through the episode loop, the single-agent env);
    return the observations of the steps with a choice, the teacher's label of each (``label``,
    shape ``(T,)``), the dispatcher's choice of each with ``rule_weight`` (``rule``), and the
    metrics of the day (so far, for a partial day)."""
    from agents.controllers.dispatcher import DispatcherController
    from agents.controllers.episode import run_episode
    from agents.controllers.gcn import GCNController
    from agents.controllers.prior import RulePriorController
    from marl_vertiport.config import from_dict
    from marl_vertiport.gym_env import VertiportEnv

    torch.set_num_threads(1)
    if not task.labelled and task.learner is None:
        raise ValueError("a day without labels needs a learner to drive it")
    env = VertiportEnv(config=from_dict(task.env_config))
    teacher = (make_teacher(task.teacher, task.planner_horizon, task.planner_margin, task.seed,
                            learner=task.learner,
                            rule_weight=task.rule_weight if task.propose_with_prior else 0.0,
                            **task.planner_options)
               if task.labelled else None)
    # One dispatcher gives the day's rule: the choice logged and the learner's prior (it keeps
    # no state between decisions, so the two may share it).
    rule = DispatcherController() if task.rule_weight > 0 else None
    learner = GCNController(task.learner) if task.learner is not None else None
    if learner is not None and rule is not None:
        learner = RulePriorController(learner, rule, task.rule_weight)
    log = DemonstrationLog(with_rule=rule is not None)
    driver = Demonstrator(teacher, learner, task.noise, np.random.default_rng([task.seed, 1]), log,
                          rule)
    metrics = run_episode(env, driver, task.seed, max_steps=task.steps)
    env.close()
    if hasattr(teacher, "close"):
        teacher.close()
    return log.arrays(), metrics


def pad_day(data: dict[str, np.ndarray], max_nodes: int, max_evtols: int) -> dict[str, np.ndarray]:
    """A day's decisions padded to ``max_nodes`` vertiport nodes and ``max_evtols`` eVTOLs
    (agents/gcn/padding.py), labels (and the rule's choices) moved to the padded action space."""
    n_nodes = data["port_nodes"].shape[1]
    out = pad_observation({k: data[k] for k in ACTOR_GROUPS}, max_nodes, max_evtols)
    for key in ("label", "rule"):
        if key in data:
            out[key] = np.asarray(to_padded_action(data[key], n_nodes, max_nodes), dtype=np.int64)
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


def _with_battery(env_config: dict[str, Any], pct: float) -> dict[str, Any]:
    """``env_config`` with every battery starting at ``pct`` %."""
    return {**env_config, "battery": {**env_config.get("battery", {}), "initial_pct": float(pct)}}


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
                    labelled=not last, rule_weight=pre.rule_weight,
                    propose_with_prior=pre.propose_with_prior)
            for d, (conf, steps) in enumerate(zip(configs, lengths))]


