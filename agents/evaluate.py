"""Evaluate controllers on the paper's two cases: per-episode metrics, confidence intervals,
the paper's case-study and action-distribution charts, and a Markdown report.

Every agent plays the same held-out days (``EVAL_SEEDS[:N]``) of every case through the AEC
API; an episode is fully determined by (agent, case, seed), so the numbers do not depend on how
many worker processes run them.

Usage::

    python -m agents.evaluate --agents random fcfs heuristic --episodes 50 --out runs/eval
    python -m agents.evaluate --agents random --episodes 3 --set schedule.episode_steps=60
    python -m agents.evaluate --agents random fcfs heuristic --out docs/results \\
        --report docs/results.md

Outputs in ``--out``: ``episodes.csv``, ``summary.csv``, ``results.json``, ``case_study.png``,
``action_distribution.png`` (and the ``--report`` file). Exit codes: 0 done, 1 a controller or
the simulation failed mid-run (the episodes completed so far are written and ``results.json``
says the run is incomplete), 2 bad input (nothing is run), 130 interrupted with Ctrl-C (partial
results written as for 1).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import multiprocessing
import os
import shlex
import signal
import sys
import time
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import yaml

from agents.base import run_aec_episode
from agents.files import write_atomic
from agents.registry import AgentSpecError, make_controller
from agents.seeds import EVAL_SEEDS, parse_seed_range

__all__ = [
    "DEFAULT_AGENTS", "DEFAULT_CONFIGS", "EpisodeRecord", "EpisodeTask", "EvalSettings",
    "Evaluation", "InputError", "bootstrap_ci", "describe", "evaluate", "format_table", "main",
    "parse_overrides", "run_task", "summarize", "write_outputs",
]

DEFAULT_AGENTS = ("random", "fcfs", "heuristic")
#: The paper's case 1 (no uncertainty) and case 2 (wind gusts, charger and take-off failures).
DEFAULT_CONFIGS = ("paper", "paper_uncertain")
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95
#: Episodes (from the first) whose action counts make the action-distribution chart.
ACTION_EPISODES = 5

#: Metric -> short label with its unit, for tables and figures.
METRIC_LABELS = {
    "steps": "steps",
    "total_reward": "total reward",
    "mean_battery_pct": "mean battery (%)",
    "good_takeoffs": "good take-offs",
    "good_landings": "good landings",
    "takeoffs": "take-offs",
    "failed_takeoffs": "failed take-offs",
    "landings": "landings",
    "mean_delay_min": "mean delay (min)",
    "collisions": "collisions",
    "avoided_conflicts": "avoided conflicts",
    "separation_losses": "separation losses",
    "contacts": "contacts",
    "battery_depletions": "depletions",
    "stranded_air": "lost in the air",
    "stranded_ground": "lost on the ground",
    "stranded": "vehicles lost",
    "service_min_lost": "service lost (min)",
    "completed_trips": "completed trips",
}
#: Columns of the printed table (agents as rows).
TABLE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                 "mean_delay_min", "collisions", "separation_losses", "stranded_air",
                 "stranded_ground", "service_min_lost")
#: Panels of the case-study chart.
FIGURE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                  "mean_delay_min", "collisions", "stranded_air", "stranded_ground")
#: Which way is better for a metric (+1 higher, -1 lower), for the report's generated findings.
DIRECTION = {"total_reward": 1, "mean_battery_pct": 1, "good_takeoffs": 1, "good_landings": 1,
             "mean_delay_min": -1, "collisions": -1, "separation_losses": -1,
             "battery_depletions": -1, "stranded_air": -1, "stranded_ground": -1,
             "stranded": -1, "service_min_lost": -1}
#: The error of a run stopped with Ctrl-C (exit code 130 rather than 1).
INTERRUPTED = "interrupted (Ctrl-C)"
CASE_LABELS = {"paper": "case 1, no uncertainty", "paper_uncertain": "case 2, with uncertainty",
               "paper_uncertain_10": "case 2 with every uncertainty at 10 %"}

Overrides = tuple[tuple[str, Any], ...]


class InputError(ValueError):
    """Bad command-line input (agent, config, override, episode count); nothing was run."""


SUITE_DIR = Path(__file__).resolve().parents[1] / "configs" / "suites"


@dataclass(frozen=True)
class SuiteConfig:
    """A named evaluation suite (``configs/suites/<name>.yaml``): which agents play which
    cases on which seeds."""

    name: str
    configs: tuple[str, ...]
    """Cases: env config names in configs/env/ or YAML paths."""
    agents: tuple[str, ...] = DEFAULT_AGENTS
    seeds: str = ""
    """``"START:STOP"`` (validation or test seeds); empty: ``EVAL_SEEDS[:episodes]``."""
    episodes: int = 50
    """Days per agent and case when ``seeds`` is not given."""


def load_suite(spec: str | Path) -> SuiteConfig:
    """A suite by name (configs/suites/) or YAML path; errors name the file and the key."""
    from marl_vertiport.config import ConfigError, load_yaml_dataclass

    try:
        suite = load_yaml_dataclass(SuiteConfig, spec, SUITE_DIR, "suite")
    except ConfigError as exc:
        raise InputError(str(exc)) from None
    if not suite.configs or not suite.agents:
        raise InputError(f"suite {spec}: configs and agents must not be empty")
    return suite


# ============================================================================ settings, tasks


@dataclass(frozen=True)
class EvalSettings:
    """What to evaluate: agents x cases x the first ``episodes`` evaluation seeds."""

    agents: tuple[str, ...] = DEFAULT_AGENTS
    configs: tuple[str, ...] = DEFAULT_CONFIGS
    episodes: int = 50
    overrides: Overrides = ()
    bootstrap: int = BOOTSTRAP_RESAMPLES
    bootstrap_seed: int = BOOTSTRAP_SEED
    confidence: float = CONFIDENCE
    first_seed: int | None = None
    """Seeds ``first_seed .. first_seed + episodes - 1`` (``--seeds``) instead of
    ``EVAL_SEEDS[:episodes]``."""

    @property
    def seeds(self) -> tuple[int, ...]:
        if self.first_seed is not None:
            return tuple(range(self.first_seed, self.first_seed + self.episodes))
        return tuple(EVAL_SEEDS[: self.episodes])

    @property
    def seeds_rule(self) -> str:
        """How the seeds were chosen, in words for the report and results.json."""
        if self.first_seed is not None:
            return f"--seeds {self.first_seed}:{self.first_seed + self.episodes}"
        return f"EVAL_SEEDS[:{self.episodes}] (agents.seeds)"

    def tasks(self) -> list[EpisodeTask]:
        """Every episode to run, in (agent, case, episode) order."""
        return [EpisodeTask(agent, config, k, seed, self.overrides)
                for agent in self.agents for config in self.configs
                for k, seed in enumerate(self.seeds)]

    def to_json(self) -> dict[str, Any]:
        return {"agents": list(self.agents), "configs": list(self.configs),
                "episodes": self.episodes, "seeds": list(self.seeds),
                "seeds_rule": self.seeds_rule,
                "overrides": {k: v for k, v in self.overrides},
                "bootstrap": {"resamples": self.bootstrap, "seed": self.bootstrap_seed,
                              "confidence": self.confidence, "method": "percentile"}}


@dataclass(frozen=True)
class EpisodeTask:
    """One episode: everything a worker process needs to run it."""

    agent: str
    config: str
    episode: int
    seed: int
    overrides: Overrides = ()


@dataclass
class EpisodeRecord:
    """The outcome of one episode: its metrics, or the error that stopped it."""

    task: EpisodeTask
    metrics: dict[str, Any] | None = None
    error: str | None = None
    seconds: float = 0.0


@dataclass
class Evaluation:
    """Everything an evaluation produced; ``error`` is set when it stopped early."""

    settings: EvalSettings
    records: list[EpisodeRecord]
    action_names: dict[str, list[str]]
    metrics: list[str] = field(default_factory=list)
    summary: list[dict[str, Any]] = field(default_factory=list)
    error: str | None = None
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        return self.error is None and len(self.records) == len(self.settings.tasks())

    def stat(self, agent: str, config: str, metric: str) -> dict[str, Any] | None:
        """The summary row of one (agent, case, metric), or None if it has no episode."""
        for row in self.summary:
            if (row["agent"], row["config"], row["metric"]) == (agent, config, metric):
                return row
        return None


def parse_overrides(items: Iterable[str]) -> Overrides:
    """``["schedule.episode_steps=60"]`` -> ``(("schedule.episode_steps", 60),)``; values are
    parsed with ``yaml.safe_load`` (numbers, booleans, lists)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--set {item!r}: expected KEY=VALUE, e.g. schedule.episode_steps=60")
        try:
            out[key.strip()] = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise InputError(f"--set {item!r}: the value is not valid YAML ({exc})") from None
    return tuple(out.items())


# ============================================================================ worker side

_ENV_CACHE: dict[tuple[str, str], Any] = {}


def _cached_env(config: str, overrides: Overrides) -> Any:
    """The AEC env of a case, built once per process (each holds its own pybullet client)."""
    from marl_vertiport import vertiport_v0

    key = (config, repr(overrides))
    if key not in _ENV_CACHE:
        _ENV_CACHE[key] = vertiport_v0.env(config=config, **dict(overrides))
    return _ENV_CACHE[key]


def _drop_env(config: str, overrides: Overrides) -> None:
    env = _ENV_CACHE.pop((config, repr(overrides)), None)
    if env is not None:
        env.close()


def close_envs() -> None:
    """Close every env this process has cached."""
    for key in list(_ENV_CACHE):
        _ENV_CACHE.pop(key).close()


def _plain(value: Any) -> Any:
    """numpy scalars and arrays -> Python numbers and lists (for JSON and CSV)."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    return value


def run_task(task: EpisodeTask) -> EpisodeRecord:
    """Run one episode with a fresh controller; errors come back in the record, not raised."""
    start = time.perf_counter()
    try:
        env = _cached_env(task.config, task.overrides)
        controller = make_controller(task.agent)
        metrics = run_aec_episode(env, controller, seed=task.seed)
    except Exception as exc:  # an illegal action (ValueError), or a controller that crashed
        _drop_env(task.config, task.overrides)  # the env stopped mid-episode
        kind = "" if isinstance(exc, ValueError) else f"{type(exc).__name__}: "
        return EpisodeRecord(task, error=f"{kind}{exc}", seconds=time.perf_counter() - start)
    plain = {k: _plain(v) for k, v in metrics.items()}
    return EpisodeRecord(task, metrics=plain, seconds=time.perf_counter() - start)


def _worker_init() -> None:
    """Workers ignore Ctrl-C: the parent stops handing out work and lets them finish."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# ============================================================================ running


def validate(settings: EvalSettings) -> dict[str, list[str]]:
    """Check every agent and case before anything runs; return each case's action names.

    Raises:
        InputError: an unknown agent, an import path that does not load, a bad config or
            override, or an episode count outside ``1 .. len(EVAL_SEEDS)``.
    """
    from marl_vertiport.config import ConfigError, load_config

    if settings.first_seed is None and not 1 <= settings.episodes <= len(EVAL_SEEDS):
        raise InputError(f"--episodes must be between 1 and {len(EVAL_SEEDS)}, "
                         f"got {settings.episodes}")
    if settings.bootstrap < 1:
        raise InputError(f"--bootstrap must be >= 1, got {settings.bootstrap}")
    if not settings.agents or not settings.configs:
        raise InputError("at least one agent and one config are needed")
    for spec in settings.agents:
        try:
            make_controller(spec)
        except AgentSpecError as exc:
            raise InputError(str(exc)) from None
        except Exception as exc:  # the class loaded but could not be built
            raise InputError(f"agent {spec!r}: building the controller failed: "
                             f"{type(exc).__name__}: {exc}") from None
    names: dict[str, list[str]] = {}
    for config in settings.configs:
        try:
            load_config(config, **dict(settings.overrides))
        except (ConfigError, OSError) as exc:
            raise InputError(f"config {config!r}: {exc}") from None
        sim = _cached_env(config, settings.overrides).unwrapped.sim
        names[config] = list(sim.actions.names(sim.layout))
    return names


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, file=sys.stderr, unit="episode", disable=not enabled,
                dynamic_ncols=True)


def _describe_failure(record: EpisodeRecord) -> str:
    t = record.task
    return (f"agent {t.agent!r} failed in case {t.config!r} at seed {t.seed} "
            f"(episode {t.episode}): {record.error}")


def _run_serial(tasks: Sequence[EpisodeTask], on_done: Callable[[EpisodeRecord], bool]) -> None:
    for task in tasks:
        if not on_done(run_task(task)):
            return


def _run_pool(tasks: Sequence[EpisodeTask], workers: int,
              on_done: Callable[[EpisodeRecord], bool]) -> str | None:
    """Run ``tasks`` on ``workers`` spawned processes; stop handing out work as soon as
    ``on_done`` returns False. Returns an error message if the pool itself broke."""
    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
    futures: list[Future] = []
    seen: set[int] = set()
    problem: str | None = None
    try:
        futures = [pool.submit(run_task, task) for task in tasks]
        for i, fut in _completed_in_any_order(futures):
            seen.add(i)
            if not on_done(fut.result()):
                break
    except KeyboardInterrupt:
        problem = INTERRUPTED
    except Exception as exc:  # BrokenProcessPool: a worker died (crash, out of memory)
        problem = f"a worker process failed: {type(exc).__name__}: {exc}"
    finally:
        for fut in futures:
            fut.cancel()
        pool.shutdown(wait=True, cancel_futures=True)
    # Episodes that were already running when the run stopped finished: keep them.
    for i, fut in enumerate(futures):
        if i not in seen and fut.done() and not fut.cancelled() and fut.exception() is None:
            on_done(fut.result())
    return problem


def _completed_in_any_order(futures: list[Future]) -> Iterable[tuple[int, Future]]:
    index = {id(f): i for i, f in enumerate(futures)}
    for fut in as_completed(futures):
        yield index[id(fut)], fut


def run_episodes(settings: EvalSettings, workers: int = 1,
                 progress: bool = True) -> tuple[list[EpisodeRecord], str | None]:
    """Run every episode of ``settings``; stop at the first failure.

    Returns the completed episodes sorted by (agent, case, episode), and the error that stopped
    the run (None if it ran to the end).
    """
    tasks = settings.tasks()
    done: list[EpisodeRecord] = []
    failure: list[str] = []
    bar = _progress(len(tasks), progress)

    def on_done(record: EpisodeRecord) -> bool:
        if record.error is not None:
            if not failure:
                failure.append(_describe_failure(record))
            return False
        done.append(record)
        bar.set_description(f"{record.task.agent} / {record.task.config}", refresh=False)
        bar.update(1)
        return not failure

    try:
        if workers <= 1:
            try:
                _run_serial(tasks, on_done)
            except KeyboardInterrupt:
                failure.append(INTERRUPTED)
        else:
            problem = _run_pool(tasks, min(workers, len(tasks)), on_done)
            if problem and not failure:
                failure.append(problem)
    finally:
        bar.close()
    order = {(a, c): (i, j) for i, a in enumerate(settings.agents)
             for j, c in enumerate(settings.configs)}
    done.sort(key=lambda r: (*order[(r.task.agent, r.task.config)], r.task.episode))
    return done, (failure[0] if failure else None)


# ============================================================================ statistics


def bootstrap_ci(values: Sequence[float], resamples: int = BOOTSTRAP_RESAMPLES,
                 confidence: float = CONFIDENCE, seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of the mean.

    The resampling generator is seeded with ``seed`` on every call, so the interval depends
    only on the values and the arguments. Constant (or single) values give a zero-width
    interval at that value.
    """
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    if x.size == 1 or np.all(x == x[0]):
        return float(x[0]), float(x[0])
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(resamples, x.size))].mean(axis=1)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(means, [alpha, 1.0 - alpha])
    return float(low), float(high)


def describe(values: Sequence[float], resamples: int = BOOTSTRAP_RESAMPLES,
             confidence: float = CONFIDENCE, seed: int = BOOTSTRAP_SEED) -> dict[str, float]:
    """Mean, standard deviation (ddof=1 when n > 1, else 0), bootstrap CI of the mean, n."""
    x = np.asarray(values, dtype=float)
    n = int(x.size)
    if n == 0:
        return {"mean": math.nan, "std": math.nan, "ci_low": math.nan, "ci_high": math.nan, "n": 0}
    low, high = bootstrap_ci(x, resamples, confidence, seed)
    return {"mean": float(x.mean()), "std": float(x.std(ddof=1)) if n > 1 else 0.0,
            "ci_low": low, "ci_high": high, "n": n}


def scalar_metrics(records: Sequence[EpisodeRecord]) -> list[str]:
    """Names of the scalar metrics, in the order the simulator reports them."""
    for record in records:
        if record.metrics is not None:
            return [k for k, v in record.metrics.items()
                    if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return []


def summarize(records: Sequence[EpisodeRecord], settings: EvalSettings,
              metrics: Sequence[str]) -> list[dict[str, Any]]:
    """One row per agent x case x metric (cases with no completed episode are left out)."""
    rows = []
    for agent in settings.agents:
        for config in settings.configs:
            group = [r.metrics for r in records
                     if (r.task.agent, r.task.config) == (agent, config) and r.metrics]
            if not group:
                continue
            for metric in metrics:
                stats = describe([m[metric] for m in group], settings.bootstrap,
                                 settings.confidence, settings.bootstrap_seed)
                rows.append({"agent": agent, "config": config, "metric": metric, **stats})
    return rows


def action_shares(evaluation: Evaluation, agent: str, config: str,
                  episodes: int = ACTION_EPISODES) -> dict[str, float]:
    """Share (%) of each action of the acting eVTOL over the first ``episodes`` episodes."""
    names = evaluation.action_names[config]
    counts = np.zeros(len(names))
    for r in evaluation.records:
        t = r.task
        if (t.agent, t.config) == (agent, config) and t.episode < episodes and r.metrics:
            counts += np.asarray(r.metrics["action_counts"], dtype=float)
    total = counts.sum()
    shares = 100.0 * counts / total if total > 0 else counts
    return dict(zip(names, shares.tolist()))


def evaluate(settings: EvalSettings, workers: int = 1, progress: bool = True,
             action_names: dict[str, list[str]] | None = None) -> Evaluation:
    """Validate, run every episode and summarise. Raises :class:`InputError` on bad input."""
    if action_names is None:
        action_names = validate(settings)
    start = time.perf_counter()
    try:
        records, error = run_episodes(settings, workers, progress)
    finally:
        close_envs()
    metrics = scalar_metrics(records)
    return Evaluation(settings, records, action_names, metrics,
                      summarize(records, settings, metrics), error,
                      seconds=time.perf_counter() - start)


# ============================================================================ text output


def case_label(config: str) -> str:
    """``paper`` -> ``paper (case 1, no uncertainty)``; other configs by name."""
    return f"{config} ({CASE_LABELS[config]})" if config in CASE_LABELS else config


def agent_label(spec: str) -> str:
    """Short display name: the class name of an import path, else the spec."""
    return spec.rsplit(":", 1)[-1] if ":" in spec else spec


def _decimals(half_width: float, mean: float) -> int:
    scale = half_width if half_width > 0 else abs(mean)
    if not math.isfinite(scale) or scale < 1:
        return 2
    return 1 if scale < 10 else 0


def format_pm(row: dict[str, Any]) -> str:
    """``mean ± half-width of the CI``."""
    half = (row["ci_high"] - row["ci_low"]) / 2.0
    d = _decimals(half, row["mean"])
    return f"{row['mean']:.{d}f} ± {half:.{d}f}"


def format_interval(row: dict[str, Any]) -> str:
    """``mean [ci_low, ci_high]``."""
    half = (row["ci_high"] - row["ci_low"]) / 2.0
    d = _decimals(half, row["mean"])
    return f"{row['mean']:.{d}f} [{row['ci_low']:.{d}f}, {row['ci_high']:.{d}f}]"


def format_table(evaluation: Evaluation) -> str:
    """The console table: one block per case, agents as rows, mean ± 95 % CI half-width."""
    metrics = [m for m in TABLE_METRICS if m in evaluation.metrics]
    pct = round(100 * evaluation.settings.confidence)
    blocks = []
    for config in evaluation.settings.configs:
        rows = [[agent] + [format_pm(evaluation.stat(agent, config, m)) for m in metrics]
                for agent in evaluation.settings.agents
                if evaluation.stat(agent, config, metrics[0]) is not None] if metrics else []
        if not rows:
            continue
        n = max(evaluation.stat(r[0], config, metrics[0])["n"] for r in rows)
        header = ["agent"] + [METRIC_LABELS.get(m, m) for m in metrics]
        widths = [max(len(str(line[i])) for line in [header] + rows) for i in range(len(header))]
        title = (f"{case_label(config)}: mean ± {pct} % CI half-width over {n} episode"
                 f"{'s' if n != 1 else ''}")
        lines = [title, "  ".join(h.ljust(w) if i == 0 else h.rjust(w)
                                  for i, (h, w) in enumerate(zip(header, widths)))]
        lines.append("  ".join("-" * w for w in widths))
        for row in rows:
            lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                                   for i, (c, w) in enumerate(zip(row, widths))))
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


# ============================================================================ files


def _csv_text(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


def episodes_csv(evaluation: Evaluation) -> str:
    """One row per completed episode: agent, config, episode, seed, every scalar metric."""
    header = ["agent", "config", "episode", "seed", *evaluation.metrics]
    rows = ([r.task.agent, r.task.config, r.task.episode, r.task.seed,
             *(r.metrics[m] for m in evaluation.metrics)] for r in evaluation.records)
    return _csv_text(header, rows)


def summary_csv(evaluation: Evaluation) -> str:
    """One row per agent x case x metric: mean, std, ci_low, ci_high, n."""
    header = ["agent", "config", "metric", "mean", "std", "ci_low", "ci_high", "n"]
    return _csv_text(header, ([row[k] for k in header] for row in evaluation.summary))


def results_json(evaluation: Evaluation, command: str) -> str:
    """Everything: settings, per-episode metrics (with action counts), the summary."""
    doc = {
        "complete": evaluation.complete,
        "error": evaluation.error,
        "command": command,
        "settings": evaluation.settings.to_json(),
        "action_names": evaluation.action_names,
        "metrics": evaluation.metrics,
        "episodes": [{"agent": r.task.agent, "config": r.task.config, "episode": r.task.episode,
                      "seed": r.task.seed, "metrics": r.metrics} for r in evaluation.records],
        "summary": evaluation.summary,
    }
    return json.dumps(doc, indent=1, allow_nan=True) + "\n"


# ============================================================================ figures


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
    return buf.getvalue()


def _case_colors(configs: Sequence[str]) -> dict[str, Any]:
    palette = ["#2f6fb0", "#e08a1e", "#4a9a4a", "#b04a6f", "#6f5aa8", "#8a6d3b"]
    return {c: palette[i % len(palette)] for i, c in enumerate(configs)}


def case_study_figure(evaluation: Evaluation) -> bytes:
    """The paper's case-study chart: one panel per metric, bars per agent and case, 95 % CIs."""
    plt = _pyplot()
    s = evaluation.settings
    metrics = [m for m in FIGURE_METRICS if m in evaluation.metrics]
    ncols = 3
    nrows = max(1, math.ceil(len(metrics) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.7 * nrows), squeeze=False)
    colors = _case_colors(s.configs)
    x = np.arange(len(s.agents))
    width = 0.8 / len(s.configs)
    for ax, metric in zip(axes.flat, metrics):
        for j, config in enumerate(s.configs):
            rows = [evaluation.stat(a, config, metric) for a in s.agents]
            mean = np.array([r["mean"] if r else np.nan for r in rows])
            low = np.array([r["ci_low"] if r else np.nan for r in rows])
            high = np.array([r["ci_high"] if r else np.nan for r in rows])
            ax.bar(x + (j - (len(s.configs) - 1) / 2) * width, mean, width,
                   yerr=np.vstack([mean - low, high - mean]), capsize=4, color=colors[config],
                   error_kw={"elinewidth": 1.2, "ecolor": "#222222"}, label=case_label(config))
        ax.set_title(METRIC_LABELS.get(metric, metric).capitalize(), fontsize=12)
        ax.set_ylabel(_unit_label(metric), fontsize=10)
        ax.set_xticks(x, [agent_label(a) for a in s.agents],
                      rotation=20 if max(len(agent_label(a)) for a in s.agents) > 9 else 0,
                      fontsize=10)
        ax.axhline(0, color="#555555", linewidth=0.8)
        if all(r["ci_low"] >= 0 for r in evaluation.summary if r["metric"] == metric):
            ax.set_ylim(bottom=0, top=None if ax.get_ylim()[1] > 0 else 1)  # counts, %, minutes
        ax.grid(axis="y", alpha=0.3)
        ax.set_axisbelow(True)
    for ax in list(axes.flat)[len(metrics):]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=len(s.configs), fontsize=11,
               frameon=False, bbox_to_anchor=(0.5, 1.0))
    n = max((r["n"] for r in evaluation.summary), default=0)
    fig.suptitle(f"Case study: mean per day over {n} evaluation days, error bars = "
                 f"{round(100 * s.confidence)} % bootstrap CI", fontsize=13, y=1.05)
    fig.tight_layout()
    data = _png(fig)
    plt.close(fig)
    return data


def _unit_label(metric: str) -> str:
    units = {"total_reward": "reward per day", "mean_battery_pct": "battery (%)",
             "mean_delay_min": "delay per eVTOL (min)"}
    return units.get(metric, "count per day")


def action_distribution_figure(evaluation: Evaluation, episodes: int = ACTION_EPISODES) -> bytes:
    """The paper's action-distribution chart: share of each action per agent, cases side by
    side, over the first ``episodes`` evaluation episodes."""
    plt = _pyplot()
    s = evaluation.settings
    used = min(episodes, s.episodes)
    names: list[str] = []
    for config in s.configs:
        names += [n for n in evaluation.action_names[config] if n not in names]
    shares = {(a, c): action_shares(evaluation, a, c, used) for a in s.agents for c in s.configs}
    ncols = min(3, len(s.agents))
    nrows = math.ceil(len(s.agents) / ncols)
    height = 0.26 * len(names) * len(s.configs) + 1.5
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.2 * ncols, max(4.0, height) * nrows),
                             squeeze=False, sharey=True)
    colors = _case_colors(s.configs)
    y = np.arange(len(names))
    bar = 0.8 / len(s.configs)
    top = max([v for d in shares.values() for v in d.values()] + [1.0])
    for ax, agent in zip(axes.flat, s.agents):
        for j, config in enumerate(s.configs):
            vals = np.array([shares[(agent, config)].get(n, 0.0) for n in names])
            pos = y + (j - (len(s.configs) - 1) / 2) * bar
            ax.barh(pos, vals, bar, color=colors[config], label=case_label(config))
            for p, v in zip(pos, vals):
                if v > 0:
                    ax.text(v + top * 0.01, p, f"{v:.1f}" if v >= 0.1 else "<0.1",
                            va="center", fontsize=8)
        ax.set_title(agent_label(agent), fontsize=12)
        ax.set_yticks(y, names, fontsize=9)
        ax.set_ylim(len(names) - 0.5, -0.5)  # first action on top (set, not toggled: shared y)
        ax.set_xlim(0, top * 1.18)
        ax.set_xlabel("share of the acting eVTOL's actions (%)", fontsize=10)
        ax.grid(axis="x", alpha=0.3)
        ax.set_axisbelow(True)
    for ax in list(axes.flat)[len(s.agents):]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=len(s.configs), fontsize=11,
               frameon=False, bbox_to_anchor=(0.5, 1.0))
    seeds = s.seeds[:used]
    fig.suptitle(f"Action distribution over the first {used} evaluation day"
                 f"{'s' if used != 1 else ''} (seeds {seeds[0]}–{seeds[-1]})",
                 fontsize=13, y=1.04)
    fig.tight_layout()
    data = _png(fig)
    plt.close(fig)
    return data


# ============================================================================ report


METRIC_MEANINGS = """\
**What the metrics mean.** Every number is per simulated day (one episode of {steps}
steps) and is averaged over the evaluation days.
*Total reward* is the sum over the day's steps of the reward of the eVTOL acting at that step
(the paper's weighted sum of take-off, landing, battery, delay and safety terms).
*Mean battery* is the fleet's mean state of charge (%), averaged over the steps.
*Good take-offs* / *good landings* count take-offs and landing clearances that earned the
positive take-off / landing term (on time and with enough charge); *take-offs* and *landings*
count all of them, *failed take-offs* those lost to the uncertainty of case 2.
*Mean delay* is the lateness (minutes) of operations done more than the tolerance late, plus
those still pending at the end, summed per eVTOL and averaged over the fleet.
*Collisions* are the paper's collisions: steps in which a conflict was predicted for the acting
eVTOL and it was not told to avoid it (safety term S = -5); *avoided conflicts* are steps with
S = +5. *Separation losses* (two eVTOLs closer than the minimum separation during a step) and
*contacts* (two bodies touching) are measured by the physics engine and do not enter the
reward. *Lost in the air* counts eVTOLs whose battery ran out in flight (an emergency landing;
out of service for the rest of the day; the paper's battery depletions); *lost on the ground*
counts eVTOLs left on a normal port with a battery from which no flight the ATC may clear
reaches a charger (they never serve again that day); *service lost* adds up the minutes from
each loss to the end of the day. *Completed trips* are touchdowns after a landing clearance.
"""


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return a["ci_low"] <= b["ci_high"] and b["ci_low"] <= a["ci_high"]


def _ranking_findings(evaluation: Evaluation, config: str) -> list[str]:
    """One generated sentence per directional metric: which agent's mean is best, and whether
    its CI separates it from the runner-up."""
    agents = [a for a in evaluation.settings.agents
              if evaluation.stat(a, config, "total_reward") is not None]
    if len(agents) < 2:
        return []
    out = []
    for metric, sign in DIRECTION.items():
        if metric not in evaluation.metrics:
            continue
        rows = sorted((evaluation.stat(a, config, metric) for a in agents),
                      key=lambda r: -sign * r["mean"])
        best, second = rows[0], rows[1]
        word = "highest" if sign > 0 else "lowest"
        label = METRIC_LABELS.get(metric, metric)
        if best["mean"] == second["mean"]:
            tied = [agent_label(r["agent"]) for r in rows if r["mean"] == best["mean"]]
            d = _decimals((best["ci_high"] - best["ci_low"]) / 2.0, best["mean"])
            out.append(f"{label}: {', '.join(tied)} have the same mean, {best['mean']:.{d}f}.")
            continue
        verdict = ("the 95 % CIs overlap, so these episodes do not separate the two"
                   if _overlap(best, second) else "the 95 % CIs do not overlap")
        out.append(f"{label}: {word} mean for {agent_label(best['agent'])} "
                   f"({format_interval(best)}), next {agent_label(second['agent'])} "
                   f"({format_interval(second)}); {verdict}.")
    return out


def _case_change_findings(evaluation: Evaluation) -> list[str]:
    """Per agent: how the means move from the first case to each other case."""
    s = evaluation.settings
    if len(s.configs) < 2:
        return []
    base, out = s.configs[0], []
    for other in s.configs[1:]:
        for agent in s.agents:
            parts = []
            for metric in ("total_reward", "good_takeoffs", "good_landings", "mean_delay_min",
                           "collisions", "battery_depletions"):
                a, b = (evaluation.stat(agent, base, metric), evaluation.stat(agent, other, metric))
                if a is None or b is None:
                    continue
                d = _decimals((a["ci_high"] - a["ci_low"]) / 2, a["mean"])
                tag = "CIs overlap" if _overlap(a, b) else "CIs do not overlap"
                parts.append(f"{METRIC_LABELS[metric]} {a['mean']:.{d}f} → {b['mean']:.{d}f} "
                             f"({tag})")
            if parts:
                out.append(f"{agent_label(agent)}, {base} → {other}: " + "; ".join(parts) + ".")
    return out


def _report_table(evaluation: Evaluation, config: str) -> str:
    agents = [a for a in evaluation.settings.agents
              if evaluation.stat(a, config, evaluation.metrics[0]) is not None]
    metrics = [m for m in evaluation.metrics if m != "steps"]
    lines = ["| metric | " + " | ".join(agent_label(a) for a in agents) + " |",
             "|---|" + "---:|" * len(agents)]
    for metric in metrics:
        cells = [format_interval(evaluation.stat(a, config, metric)) for a in agents]
        lines.append(f"| {METRIC_LABELS.get(metric, metric)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def report_markdown(evaluation: Evaluation, command: str, report_path: Path,
                    figures: dict[str, Path]) -> str:
    """The Markdown report: provenance, one table per case, the figures, generated findings."""
    s = evaluation.settings
    seeds = s.seeds
    n = s.episodes
    pct = round(100 * s.confidence)
    steps = evaluation.stat(s.agents[0], s.configs[0], "steps")
    parts = ["# Evaluation results", "",
             f"Produced by `{command}`.", "",
             f"Every agent played the same {n} evaluation day{'s' if n != 1 else ''} of each case "
             f"(seeds {seeds[0]} … {seeds[-1]}, `{s.seeds_rule}`; `agents/seeds.py` keeps "
             "them apart from every training seed), "
             "through the PettingZoo AEC API, with a fresh controller per day. "
             f"Cells are `mean [{pct} % CI]`, the CI being a percentile bootstrap of the mean "
             f"({s.bootstrap} resamples, generator seed {s.bootstrap_seed}). Per-episode numbers "
             "are in `episodes.csv`, the summary in `summary.csv` and everything in "
             "`results.json`, next to the figures."]
    if s.overrides:
        parts += ["", "Config overrides: " + ", ".join(f"`{k}={v!r}`" for k, v in s.overrides)
                  + "."]
    for config in s.configs:
        parts += ["", f"## {case_label(config)}", "", _report_table(evaluation, config)]
        findings = _ranking_findings(evaluation, config)
        if findings:
            parts += ["", "What these numbers show:", ""] + [f"- {f}" for f in findings]
    parts += ["", "## Figures", ""]
    for title, key in (("Case study", "case_study"),
                       ("Action distribution", "action_distribution")):
        rel = Path(os.path.relpath(figures[key], report_path.parent)).as_posix()
        parts.append(f"![{title}]({rel})")
        parts.append("")
    used = min(ACTION_EPISODES, n)
    parts.append(f"The case-study chart shows the mean per day with {pct} % CI error bars; the "
                 f"action-distribution chart the share of each action executed by the acting "
                 f"eVTOL over the first {used} evaluation day{'s' if used != 1 else ''}.")
    changes = _case_change_findings(evaluation)
    if changes:
        parts += ["", "## From one case to the other", ""] + [f"- {c}" for c in changes]
    parts += ["", "## Metrics", "",
              METRIC_MEANINGS.format(steps=f"{steps['mean']:g}" if steps else "?").strip()]
    return "\n".join(parts) + "\n"


# ============================================================================ writing it all


def write_outputs(evaluation: Evaluation, out: Path, command: str,
                  report: Path | None = None) -> list[Path]:
    """Write the files of ``evaluation`` into ``out`` (each atomically); ``results.json`` last.

    An incomplete run writes only ``episodes.csv``, ``summary.csv`` and ``results.json``
    (with ``"complete": false`` and the error). Returns the paths written.
    """
    out.mkdir(parents=True, exist_ok=True)
    written = []

    def put(name: str | Path, data: bytes | str) -> None:
        path = out / name if isinstance(name, str) else name
        write_atomic(path, data)
        written.append(path)

    put("episodes.csv", episodes_csv(evaluation))
    put("summary.csv", summary_csv(evaluation))
    if evaluation.complete:
        figures = {"case_study": out / "case_study.png",
                   "action_distribution": out / "action_distribution.png"}
        put(figures["case_study"], case_study_figure(evaluation))
        put(figures["action_distribution"], action_distribution_figure(evaluation))
        if report is not None:
            put(report, report_markdown(evaluation, command, report, figures))
    put("results.json", results_json(evaluation, command))
    return written


# ============================================================================ CLI


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m agents.evaluate", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--agents", nargs="+", default=None, metavar="AGENT",
                        help="controllers to evaluate: built-in names (random, fcfs, heuristic) "
                             f"or import paths 'package.module:Class' (default: {' '.join(DEFAULT_AGENTS)})")
    parser.add_argument("--configs", nargs="+", default=None, metavar="CONFIG",
                        help="cases: config names in configs/env/ or YAML paths "
                             f"(default: {' '.join(DEFAULT_CONFIGS)} = the paper's case 1 and case 2)")
    parser.add_argument("--episodes", type=int, default=None, metavar="N",
                        help="episodes (days) per agent and case, on seeds EVAL_SEEDS[:N] "
                             "(default: 50, the paper's protocol)")
    parser.add_argument("--suite", default=None, metavar="NAME",
                        help="an evaluation suite in configs/suites/ (or a YAML path): its "
                             "agents, cases and seeds, unless given here too")
    parser.add_argument("--seeds", default=None, metavar="START:STOP",
                        help="evaluate on seeds START .. STOP-1 instead (validation seeds "
                             "800000-999999 for development, test seeds >= 1000000 for "
                             "reported numbers; training seeds are refused)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, metavar="N",
                        help="worker processes; 1 runs in this process "
                             "(default: the number of CPU cores, %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("runs/eval"), metavar="DIR",
                        help="output folder, created if needed (default: %(default)s)")
    parser.add_argument("--report", type=Path, default=None, metavar="PATH",
                        help="also write a Markdown report there (e.g. docs/results.md)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="config override for every case, value parsed as YAML; repeatable "
                             "(e.g. --set schedule.episode_steps=60)")
    parser.add_argument("--bootstrap", type=int, default=BOOTSTRAP_RESAMPLES, metavar="N",
                        help="bootstrap resamples for the confidence intervals "
                             "(default: %(default)s)")
    parser.add_argument("--bootstrap-seed", type=int, default=BOOTSTRAP_SEED, metavar="SEED",
                        help="seed of the bootstrap's generator (default: %(default)s)")
    parser.add_argument("--no-progress", action="store_true",
                        help="do not show the progress bar on stderr")
    return parser


def _unique(items: Iterable[str]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(items))


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point; returns the exit code (0 ok, 1 failed mid-run, 2 bad input)."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(args_list)
    command = shlex.join(["python", "-m", "agents.evaluate", *args_list])
    try:
        agents, configs = args.agents or list(DEFAULT_AGENTS), args.configs or list(DEFAULT_CONFIGS)
        if args.suite is not None:
            suite = load_suite(args.suite)
            agents, configs = args.agents or list(suite.agents), args.configs or list(suite.configs)
            if args.seeds is None and args.episodes is None:
                if suite.seeds:
                    args.seeds = suite.seeds
                else:
                    args.episodes = suite.episodes
        episodes, first_seed = 50 if args.episodes is None else args.episodes, None
        if args.seeds is not None:
            try:
                seeds = parse_seed_range(args.seeds)
            except ValueError as exc:
                raise InputError(f"--seeds: {exc}") from None
            if args.episodes is not None and args.episodes != len(seeds):
                raise InputError(f"--episodes {args.episodes} and --seeds {args.seeds} "
                                 f"({len(seeds)} seeds) disagree; give one of them")
            episodes, first_seed = len(seeds), seeds.start
        settings = EvalSettings(agents=_unique(agents), configs=_unique(configs),
                                episodes=episodes, first_seed=first_seed,
                                overrides=parse_overrides(args.overrides),
                                bootstrap=args.bootstrap, bootstrap_seed=args.bootstrap_seed)
        if args.workers < 1:
            raise InputError(f"--workers must be >= 1, got {args.workers}")
        names = validate(settings)
    except InputError as exc:
        close_envs()
        print(f"error: {exc}", file=sys.stderr)
        return 2
    evaluation = evaluate(settings, workers=args.workers, progress=not args.no_progress,
                          action_names=names)
    table = format_table(evaluation)
    if table:
        print(table)
    written = write_outputs(evaluation, args.out, command, args.report)
    print(f"\n{len(evaluation.records)} episodes in {evaluation.seconds:.1f} s; wrote "
          + ", ".join(str(p) for p in written), file=sys.stderr)
    if evaluation.error is not None:
        print(f"error: {evaluation.error}", file=sys.stderr)
        print(f"error: the run is incomplete: {len(evaluation.records)} of "
              f"{len(settings.tasks())} episodes were completed and written to {args.out} "
              "(results.json has \"complete\": false); no figures or report were written",
              file=sys.stderr)
        return 130 if evaluation.error == INTERRUPTED else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
