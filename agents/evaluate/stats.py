"""Statistics over episodes: percentile-bootstrap confidence intervals and the summary
rows (one per agent, case and metric)."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from agents.evaluate.settings import (
    ACTION_EPISODES, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, CONFIDENCE, EpisodeRecord,
    EvalSettings, Evaluation,
)

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

