"""A sweep's results: the tidy per-episode CSV, the summary with bootstrap CIs, the figure of
each metric against the swept value per agent, and ``sweep.json``; written by the driver,
each file atomically."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from agents.common.files import write_atomic
from agents.evaluate.figures import png_bytes, pyplot
from agents.evaluate.metrics import METRIC_LABELS, agent_label, axis_label
from agents.evaluate.settings import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, CONFIDENCE, EpisodeRecord
from agents.evaluate.stats import describe, scalar_metrics
from agents.evaluate.tables import csv_metric, csv_text
from agents.sweep.spec import SweepSpec


@dataclass
class SweepResult:
    """What a sweep produced; ``error`` is set when it stopped early."""

    spec: SweepSpec
    records: list[EpisodeRecord]
    error: str | None = None
    seconds: float = 0.0
    backend: str = ""
    metrics: list[str] = field(default_factory=list)
    provenance: dict[str, Any] = field(default_factory=dict)
    """The code, checkpoints and machine it was made with (agents/common/provenance.py)."""

    def __post_init__(self) -> None:
        if not self.metrics:
            self.metrics = scalar_metrics(self.records)

    @property
    def complete(self) -> bool:
        return self.error is None and len(self.records) == len(self.spec.tasks())


def point_of(spec: SweepSpec, record: EpisodeRecord) -> tuple[Any, ...]:
    """The swept values of an episode, in the order of ``spec.keys``."""
    given = dict(record.task.overrides)
    return tuple(given[k] for k in spec.keys)


def sweep_csv(result: SweepResult) -> str:
    """Tidy: one row per episode; columns agent, config, each swept key, episode, seed and
    every scalar metric (floats to ``CSV_DIGITS`` significant digits, agents/evaluate/tables.py)."""
    spec = result.spec
    header = ["agent", "config", *spec.keys, "episode", "seed", *result.metrics]
    rows = ([r.task.agent, r.task.config, *point_of(spec, r), r.task.episode, r.task.seed,
             *(csv_metric(r.metrics[m]) for m in result.metrics)] for r in result.records)
    return csv_text(header, rows)


def summary_rows(result: SweepResult, resamples: int = BOOTSTRAP_RESAMPLES,
                 seed: int = BOOTSTRAP_SEED) -> list[dict[str, Any]]:
    """One row per agent x case x point x metric: mean, std, 95 % bootstrap CI, n."""
    spec = result.spec
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in result.records:
        groups.setdefault((r.task.agent, r.task.config, point_of(spec, r)), []).append(r.metrics)
    rows = []
    for (agent, config, point), group in groups.items():
        for metric in result.metrics:
            stats = describe([m[metric] for m in group], resamples, CONFIDENCE, seed)
            rows.append({"agent": agent, "config": config, **dict(zip(spec.keys, point)),
                         "metric": metric, **stats})
    return rows


def summary_csv(result: SweepResult, rows: Sequence[dict[str, Any]]) -> str:
    header = ["agent", "config", *result.spec.keys, "metric", "mean", "std", "ci_low",
              "ci_high", "n"]
    return csv_text(header, ([row[k] for k in header] for row in rows))


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def sweep_figure(result: SweepResult, rows: Sequence[dict[str, Any]]) -> bytes:
    """One panel per metric of ``spec.metrics``: its mean per day against the first swept key,
    a line per agent (and per case and value of the other keys), shaded 95 % CIs."""
    plt = pyplot()
    spec = result.spec
    metrics = [m for m in spec.metrics if m in result.metrics]
    x_key, x_values = spec.grid[0]
    numeric = _numeric(x_values)
    position = {repr(v): (float(v) if numeric else float(i)) for i, v in enumerate(x_values)}
    others = [k for k in spec.keys[1:]]
    series: dict[tuple[Any, ...], None] = {}
    for row in rows:
        series[(row["agent"], row["config"], *(row[k] for k in others))] = None
    palette = ["#2f6fb0", "#e08a1e", "#4a9a4a", "#b04a6f", "#6f5aa8", "#8a6d3b", "#3a8f9a",
               "#9a3a3a"]
    styles = ["-", "--", ":", "-."]
    agents = list(spec.agents)
    # Colour: the agent; line style: the case and the values of the other swept keys.
    variants = list(dict.fromkeys(key[1:] for key in series))
    ncols = min(3, max(1, len(metrics)))
    nrows = max(1, math.ceil(len(metrics) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.8 * ncols, 3.6 * nrows), squeeze=False)
    for ax, metric in zip(axes.flat, metrics):
        for key in series:
            agent, config, *rest = key
            mine = [r for r in rows if r["metric"] == metric and r["agent"] == agent
                    and r["config"] == config and tuple(r[k] for k in others) == tuple(rest)]
            mine.sort(key=lambda r: position[repr(r[x_key])])
            x = np.array([position[repr(r[x_key])] for r in mine])
            mean = np.array([r["mean"] for r in mine])
            low = np.array([r["ci_low"] for r in mine])
            high = np.array([r["ci_high"] for r in mine])
            color = palette[agents.index(agent) % len(palette)]
            style = styles[variants.index((config, *rest)) % len(styles)]
            label = agent_label(agent)
            if len(spec.configs) > 1:
                label += f", {config}"
            if rest:
                label += ", " + ", ".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in zip(others, rest))
            ax.plot(x, mean, style, marker="o", color=color, label=label, linewidth=1.6)
            ax.fill_between(x, low, high, color=color, alpha=0.15, linewidth=0)
        ax.set_title(METRIC_LABELS.get(metric, metric).capitalize(), fontsize=12)
        ax.set_ylabel(axis_label(metric), fontsize=10)
        ax.set_xlabel(x_key, fontsize=10)
        if not numeric:
            ax.set_xticks([position[repr(v)] for v in x_values], [str(v) for v in x_values])
        ax.grid(alpha=0.3)
        ax.set_axisbelow(True)
    for ax in list(axes.flat)[len(metrics):]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=min(4, len(labels)), fontsize=10,
               frameon=False, bbox_to_anchor=(0.5, 1.0 + 0.03 * math.ceil(len(labels) / 4)))
    seeds = spec.seeds
    fig.suptitle(f"Sweep {spec.name}: mean per day over {spec.episodes} day"
                 f"{'s' if spec.episodes != 1 else ''} (seeds {seeds[0]}–{seeds[-1]}) at each "
                 f"point, shaded: {round(100 * CONFIDENCE)} % bootstrap CI", fontsize=12,
                 y=1.06 + 0.03 * math.ceil(len(labels) / 4))
    fig.tight_layout()
    data = png_bytes(fig, result.provenance)
    plt.close(fig)
    return data


def sweep_json(result: SweepResult, rows: Sequence[dict[str, Any]], command: str) -> str:
    doc = {"complete": result.complete, "error": result.error, "command": command,
           "provenance": result.provenance, "backend": result.backend, "seconds": result.seconds,
           "episodes_done": len(result.records), "episodes_planned": len(result.spec.tasks()),
           "spec": result.spec.to_json(), "metrics": result.metrics, "summary": list(rows)}
    return json.dumps(doc, indent=1, allow_nan=True) + "\n"


def write_outputs(result: SweepResult, out: Path, command: str) -> list[Path]:
    """``sweep.csv``, ``summary.csv``, ``sweep.png`` (complete runs only) and ``sweep.json``
    (last) into ``out``, each atomically. Returns the paths written."""
    rows = summary_rows(result)
    files: list[tuple[str, bytes | str]] = [("sweep.csv", sweep_csv(result)),
                                            ("summary.csv", summary_csv(result, rows))]
    if result.complete and result.records:
        files.append(("sweep.png", sweep_figure(result, rows)))
    files.append(("sweep.json", sweep_json(result, rows, command)))
    written = []
    for name, data in files:
        write_atomic(out / name, data)
        written.append(out / name)
    return written
