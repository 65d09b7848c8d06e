"""A curves study's results, written by the driver, each file atomically:

* ``curves.csv``: tidy, one row per (config, seed, PPO iteration): environment steps and every
  column of the run's ``curves.csv`` (the episode metrics are empty in iterations in which no
  training day ended);
* ``summary.csv``: per config, metric and iteration at which a seed finished a day, over the
  seeds (each at its latest finished day, see :func:`summary_rows`): the mean and the
  interquartile mean (IQM), each with a 95 % percentile-bootstrap interval over seeds;
* ``baselines.csv``: each baseline's mean and 95 % bootstrap CI on the validation days of each
  scenario the configs train on;
* ``curves.png``: the paper's total reward, vehicles lost and unresolved conflicts per day
  against environment steps, one colour per config (mean with its interval, IQM dashed), the
  baselines as horizontal lines;
* ``curves.json``: the configs as run, their seeds and run folders, each run's wall time, the
  backend, and whether every run completed.
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from agents.common.files import write_atomic
from agents.evaluate.figures import png_bytes, pyplot
from agents.evaluate.metrics import agent_label
from agents.evaluate.settings import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, CONFIDENCE
from agents.evaluate.stats import bootstrap_ci
from agents.evaluate.tables import csv_text

#: The metrics of the curves (per training day), with their panel titles.
CURVE_METRICS = (("total_reward", "Total reward per day (paper's eq. 2)"),
                 ("stranded", "Vehicles lost per day (air + ground)"),
                 ("collisions", "Unresolved conflicts per day (S = -5)"))


@dataclass
class CurvesResult:
    """What a curves study produced: per (config label, seed) the rows of its run's curves."""

    labels: list[str]
    configs: dict[str, dict[str, Any]]
    seeds: list[int]
    runs: dict[tuple[str, int], dict[str, Any]] = field(default_factory=dict)
    run_dirs: dict[tuple[str, int], str] = field(default_factory=dict)
    baselines: list[dict[str, Any]] = field(default_factory=list)
    baseline_seeds: tuple[int, int] | None = None
    backend: str = ""
    seconds: float = 0.0
    error: str | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    """The code and machine the study ran with (agents/common/provenance.py)."""

    @property
    def complete(self) -> bool:
        return self.error is None and len(self.runs) == len(self.labels) * len(self.seeds)


def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean of the values left when the lowest and the highest
    quarter (``floor(n / 4)`` values each) are dropped; the mean for fewer than 4 values."""
    x = np.sort(np.asarray(values, dtype=float))
    cut = x.size // 4
    return float(x[cut: x.size - cut].mean())


def iqm_ci(values: Sequence[float], resamples: int = BOOTSTRAP_RESAMPLES,
           confidence: float = CONFIDENCE, seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Percentile bootstrap interval of the IQM (resampling seeds with replacement)."""
    x = np.asarray(values, dtype=float)
    if x.size == 1 or np.all(x == x[0]):
        return float(x[0]), float(x[0])
    rng = np.random.default_rng(seed)
    samples = np.sort(x[rng.integers(0, x.size, size=(resamples, x.size))], axis=1)
    cut = x.size // 4  # as iqm(), on every resample at once
    stats = samples[:, cut: x.size - cut].mean(axis=1)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(low), float(high)


#: Columns of a run's curves that are whole numbers.
_COUNTS = ("iteration", "env_steps")


def _columns(result: CurvesResult) -> list[str]:
    for rows in result.runs.values():
        if rows.get("rows"):
            return list(rows["rows"][0].keys())
    return []


def curves_csv(result: CurvesResult) -> str:
    """One row per (config, seed, iteration)."""
    columns = _columns(result)
    out = []
    for label in result.labels:
        for seed in result.seeds:
            run = result.runs.get((label, seed))
            for row in (run or {}).get("rows", []):
                out.append([label, seed, *(int(row[c]) if c in _COUNTS else row.get(c, math.nan)
                                           for c in columns)])
    return csv_text(["config", "seed", *columns], out)


def summary_rows(result: CurvesResult, resamples: int = BOOTSTRAP_RESAMPLES) -> list[dict[str, Any]]:
    """Per config, curve metric and iteration at which any seed finished a training day: each
    seed's latest finished day at or before that iteration, over the seeds that finished a day
    by then and whose run trained that iteration.

    Runs that were never broken finish their days on the same iterations, so this is each
    iteration's own days. A resumed run restarts its env copies, so its days end on other
    iterations than an unbroken seed's; its value is then the day it finished last (less than
    one day's iterations earlier), never a gap that would leave a point with fewer seeds."""
    rows = []
    for label in result.labels:
        steps: dict[int, int] = {}
        # Per metric, each seed's (last iteration its run trained, its sorted (iteration, value)).
        days: dict[str, list[tuple[int, list[tuple[int, float]]]]] = {
            m: [] for m, _ in CURVE_METRICS}
        for seed in result.seeds:
            per_metric: dict[str, list[tuple[int, float]]] = {m: [] for m, _ in CURVE_METRICS}
            trained = -1
            for row in result.runs.get((label, seed), {}).get("rows", []):
                it = int(row["iteration"])
                trained = max(trained, it)
                for metric, _ in CURVE_METRICS:
                    v = float(row.get(metric, math.nan))
                    if math.isfinite(v):
                        per_metric[metric].append((it, v))
                        steps.setdefault(it, int(row["env_steps"]))
            for metric, _ in CURVE_METRICS:
                if per_metric[metric]:
                    days[metric].append((trained, sorted(per_metric[metric])))
        grid = sorted(steps)
        for it in grid:
            for metric, _ in CURVE_METRICS:
                values = [_as_of(seed_days, it) for trained, seed_days in days[metric]
                          if seed_days[0][0] <= it <= trained]
                if not values:
                    continue
                low, high = bootstrap_ci(values, resamples)
                ilow, ihigh = iqm_ci(values, resamples)
                rows.append({"config": label, "iteration": it, "env_steps": steps[it],
                             "metric": metric, "seeds": len(values),
                             "mean": float(np.mean(values)), "ci_low": low, "ci_high": high,
                             "iqm": iqm(np.array(values)), "iqm_low": ilow, "iqm_high": ihigh})
    return rows


def _as_of(seed_days: list[tuple[int, float]], iteration: int) -> float:
    """The value of the last of ``seed_days`` (sorted ``(iteration, value)``) at or before
    ``iteration``."""
    k = bisect.bisect_right(seed_days, (iteration, math.inf)) - 1
    return seed_days[k][1]


def final_rows(summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each config's and metric's summary row at the last iteration with a finished day."""
    last: dict[tuple[str, str], dict[str, Any]] = {}
    for row in summary:
        key = (row["config"], row["metric"])
        if key not in last or row["iteration"] > last[key]["iteration"]:
            last[key] = row
    return list(last.values())


def baseline_label(base: dict[str, Any], days: tuple[int, int] | None) -> str:
    """Legend entry of a baseline's line: the agent, its scenarios and, where known, the
    validation days (seeds ``days[0]`` to ``days[1] - 1``) it was scored on."""
    where = f", validation days {days[0]}-{days[1] - 1}" if days else ""
    return f"{agent_label(base['agent'])} ({base['scenarios']}{where})"


def curves_figure(result: CurvesResult, summary: list[dict[str, Any]]) -> bytes:
    plt = pyplot()
    fig, axes = plt.subplots(1, len(CURVE_METRICS), figsize=(6.0 * len(CURVE_METRICS), 4.6))
    grays = ("0.15", "0.45", "0.65", "0.3")
    styles = (":", "-.", (0, (5, 2)), (0, (1, 3)))
    for ax, (metric, title) in zip(np.atleast_1d(axes), CURVE_METRICS):
        for n, label in enumerate(result.labels):
            rows = [r for r in summary if r["config"] == label and r["metric"] == metric]
            if not rows:
                continue
            x = np.array([r["env_steps"] for r in rows], dtype=float) / 1e6
            color = f"C{n}"
            seeds = max(r["seeds"] for r in rows)
            ax.plot(x, [r["mean"] for r in rows], color=color, marker=".",
                    label=f"{label}: mean of {seeds} seeds")
            ax.fill_between(x, [r["ci_low"] for r in rows], [r["ci_high"] for r in rows],
                            color=color, alpha=0.2)
            ax.plot(x, [r["iqm"] for r in rows], color=color, linestyle="--", linewidth=1,
                    label=f"{label}: IQM" + (" (the mean: < 4 seeds)" if seeds < 4 else ""))
        for k, base in enumerate(b for b in result.baselines if b["metric"] == metric):
            ax.axhline(base["mean"], color=grays[k % len(grays)], linestyle=styles[k % len(styles)],
                       linewidth=1.3, label=baseline_label(base, result.baseline_seeds))
        ax.set_title(title)
        ax.set_xlabel("environment steps (millions)")
        ax.grid(alpha=0.3)
    handles, labels = np.atleast_1d(axes)[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8)
    seeds = ", ".join(str(s) for s in result.seeds)
    fig.suptitle(f"Learning curves over training seeds {seeds}: training days (stochastic "
                 f"policy), 95 % bootstrap intervals over seeds")
    fig.tight_layout(rect=(0, 0.1 + 0.03 * (len(labels) // 4), 1, 0.95))
    data = png_bytes(fig, result.provenance)
    plt.close(fig)
    return data


def baselines_csv(result: CurvesResult) -> str:
    header = ["agent", "scenarios", "metric", "mean", "ci_low", "ci_high", "days"]
    return csv_text(header, ([b[k] for k in header] for b in result.baselines))


def curves_json(result: CurvesResult, command: str) -> str:
    return json.dumps({
        "command": command, "complete": result.complete, "error": result.error,
        "provenance": result.provenance, "backend": result.backend, "seconds": result.seconds, "seeds": result.seeds,
        "baseline_days": (f"validation seeds {result.baseline_seeds[0]}:{result.baseline_seeds[1]}"
                          if result.baseline_seeds else None),
        "configs": {label: result.configs[label] for label in result.labels},
        "runs": [{"config": label, "seed": seed, "run_dir": result.run_dirs.get((label, seed)),
                  "seconds": result.runs[(label, seed)]["seconds"],
                  "resumed_at": result.runs[(label, seed)].get("resumed_at"),
                  "checkpoint": result.runs[(label, seed)]["checkpoint"]}
                 for label in result.labels for seed in result.seeds
                 if (label, seed) in result.runs],
    }, indent=2)


def write_outputs(result: CurvesResult, out: Path, command: str,
                  summary: list[dict[str, Any]] | None = None) -> list[Path]:
    """Write every file of the study into ``out`` (``summary``: :func:`summary_rows` of
    ``result``, computed here when not given); returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    if summary is None:
        summary = summary_rows(result)
    header = ["config", "iteration", "env_steps", "metric", "seeds", "mean", "ci_low", "ci_high",
              "iqm", "iqm_low", "iqm_high"]
    files = {
        "curves.csv": curves_csv(result).encode(),
        "summary.csv": csv_text(header, ([r[k] for k in header] for r in summary)).encode(),
        "baselines.csv": baselines_csv(result).encode(),
        "curves.json": curves_json(result, command).encode(),
    }
    if summary:
        files["curves.png"] = curves_figure(result, summary)
    for name, data in files.items():
        write_atomic(out / name, data)
    return [out / name for name in files]
