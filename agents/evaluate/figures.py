"""The figures: the case-study chart and the action-distribution chart (PNG bytes)."""

from __future__ import annotations

import io
import math
from typing import Any, Sequence

import numpy as np

from agents.evaluate.metrics import (
    FIGURE_METRICS, METRIC_LABELS, agent_label, axis_label, case_label,
)
from agents.evaluate.settings import ACTION_EPISODES, Evaluation
from agents.evaluate.stats import action_shares

# ============================================================================ figures


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def png_bytes(fig: Any, provenance: dict[str, Any] | None = None) -> bytes:
    """The PNG of ``fig`` at the resolution of every chart of the project; ``provenance``
    (:func:`agents.common.provenance.provenance`) goes into the file's text metadata."""
    from agents.common.provenance import png_metadata

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight",
                metadata=png_metadata(provenance) if provenance else None)
    return buf.getvalue()


def _case_colors(configs: Sequence[str]) -> dict[str, Any]:
    palette = ["#2f6fb0", "#e08a1e", "#4a9a4a", "#b04a6f", "#6f5aa8", "#8a6d3b"]
    return {c: palette[i % len(palette)] for i, c in enumerate(configs)}


def case_study_figure(evaluation: Evaluation) -> bytes:
    """The paper's case-study chart: one panel per metric, bars per agent and case, 95 % CIs."""
    plt = pyplot()
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
                   # A metric that barely varies (a minimum distance) can give an interval a
                   # rounding error off its mean: bars never get a negative error.
                   yerr=np.clip(np.vstack([mean - low, high - mean]), 0.0, None), capsize=4,
                   color=colors[config],
                   error_kw={"elinewidth": 1.2, "ecolor": "#222222"}, label=case_label(config))
        ax.set_title(METRIC_LABELS.get(metric, metric).capitalize(), fontsize=12)
        ax.set_ylabel(axis_label(metric), fontsize=10)
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
    data = png_bytes(fig, evaluation.provenance)
    plt.close(fig)
    return data


def action_distribution_figure(evaluation: Evaluation, episodes: int = ACTION_EPISODES) -> bytes:
    """The paper's action-distribution chart: share of each action per agent, cases side by
    side, over the first ``episodes`` evaluation episodes."""
    plt = pyplot()
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
    data = png_bytes(fig, evaluation.provenance)
    plt.close(fig)
    return data


