"""A run's learning curves: ``curves.csv`` (one row per PPO iteration), ``warmstart.csv`` (one
per warm-start round) and the figure ``learning_curves.png`` of both."""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from agents.common.files import write_atomic
from agents.common.provenance import png_metadata, provenance
from agents.training.imitation import ROUND_METRICS
from marl_vertiport.sim.metrics import TRAINING_METRICS

#: Columns of ``warmstart.csv``: one row per warm-start round (``driver`` 0: the teacher drove,
#: 1: the actor); ``env_steps`` counts demonstration steps so far; the last row's ``kept_round``
#: is the round whose days the fit kept for PPO drove.
WARM_CURVE_KEYS = ("round", "driver", "env_steps", *ROUND_METRICS, "cross_entropy", "accuracy",
                   "kept_round")
#: Columns of ``curves.csv``: one row per PPO iteration.
#: ``actor_grad_norm`` is the actor's gradient norm before the clip (the mean over the
#: iteration's gradient steps), ``actor_clip_fraction`` the share of steps the clip scaled down
#: (agents/training/ppo.py; both 0 while the actor is frozen).
CURVE_KEYS = ("iteration", "env_steps", "steps_per_s", "mean_reward", "value_loss", "surrogate_loss",
              "entropy", "learning_rate", "actor_grad_norm", "actor_clip_fraction", *TRAINING_METRICS)


def read_curves(path: Path) -> list[dict[str, float]]:
    if not path.exists():
        return []
    with path.open() as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def write_curves(path: Path, rows: list[dict[str, float]], keys: tuple[str, ...] = CURVE_KEYS) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(keys))
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row.get(k, float("nan")) for k in keys})
    write_atomic(path, buf.getvalue())


def plot_curves(rows: list[dict[str, float]], out: Path, title: str,
                warm_rows: list[dict[str, float]] = ()) -> None:
    """The paper's learning-curve figure: reward and loss, battery, take-offs/landings, delay,
    collisions per episode against environment steps.

    ``warm_rows`` (``warmstart.csv``): the warm start's rounds come first, shaded, at the
    demonstration steps they took; each point is the mean of the round's full days (the
    teacher's round as a star, the round driven by the fit kept for PPO marked by a dotted line)
    and the imitation cross-entropy is on the loss panel's right axis. PPO's iterations follow;
    its days are driven by the sampling policy, not the greedy one the evaluation runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    offset = max((r["env_steps"] for r in warm_rows), default=0.0)
    x = (np.array([r["env_steps"] for r in rows]) + offset) / 1000.0
    xw = np.array([r["env_steps"] for r in warm_rows]) / 1000.0
    by_teacher = np.array([r.get("driver", 1.0) == 0.0 for r in warm_rows], dtype=bool)
    kept = [r["kept_round"] for r in warm_rows if math.isfinite(r.get("kept_round", float("nan")))]
    kept_x = [xw[i] for i, r in enumerate(warm_rows) if kept and r["round"] == kept[-1]]
    panels = [
        ("Total reward per episode", [("total_reward", "total reward")]),
        ("Losses", [("value_loss", "PPO value loss"), ("surrogate_loss", "PPO surrogate loss")]),
        ("Mean battery (%)", [("mean_battery_pct", "mean battery")]),
        ("Good operations per episode", [("good_takeoffs", "take-offs"), ("good_landings", "landings")]),
        ("Mean delay per eVTOL (min)", [("mean_delay_min", "delay")]),
        ("Safety events per episode", [("collisions", "collisions (S = -5)"),
                                       ("separation_losses", "separation losses"),
                                       ("contacts", "contacts"),
                                       ("separation_loss_min", "minutes in loss of separation")]),
        ("Vehicles lost per episode", [("stranded_air", "in the air"),
                                       ("stranded_ground", "on the ground"),
                                       ("stranded", "all")]),
    ]
    fig, axes = plt.subplots(2, 4, figsize=(18, 7.5))
    axes.ravel()[-1].axis("off")
    for ax, (panel_title, series) in zip(axes.ravel(), panels):
        first = panel_title.startswith("Total")
        if warm_rows:
            ax.axvspan(0.0, offset / 1000.0, color="0.9", zorder=0,
                       label="warm start (imitation)" if first else None)
        if kept_x:
            ax.axvline(kept_x[0], color="0.4", linestyle=":",
                       label="days of the fit kept for PPO" if first else None)
        losses = panel_title == "Losses"
        for n, (key, label) in enumerate(series):
            color = f"C{n}"
            if losses:  # PPO's losses only; the imitation loss goes on the right axis
                y = np.array([r.get(key, np.nan) for r in rows], dtype=float)
                ok = np.isfinite(y)
                if ok.any():
                    ax.plot(x[ok], y[ok], marker=".", color=color, label=label)
                continue
            yw = np.array([r.get(key, np.nan) for r in warm_rows], dtype=float)
            y = np.array([r.get(key, np.nan) for r in rows], dtype=float)
            xs, ys = np.concatenate([xw, x]), np.concatenate([yw, y])
            ok = np.isfinite(ys)
            if ok.any():
                ax.plot(xs[ok], ys[ok], marker=".", color=color, label=label)
            teacher = by_teacher & np.isfinite(yw)
            if teacher.any():
                ax.plot(xw[teacher], yw[teacher], marker="*", markersize=12, linestyle="none",
                        color=color, label="teacher's days" if n == 0 else None)
        if losses and warm_rows:
            ce = np.array([r.get("cross_entropy", np.nan) for r in warm_rows], dtype=float)
            ok = np.isfinite(ce)
            if ok.any():
                right = ax.twinx()
                right.plot(xw[ok], ce[ok], marker="s", color="C3", label="imitation cross-entropy")
                right.set_ylabel("imitation cross-entropy", color="C3")
                right.tick_params(axis="y", colors="C3")
                right.set_ylim(bottom=0.0)
                handles, labels = ax.get_legend_handles_labels()
                more = right.get_legend_handles_labels()
                right.legend(handles + more[0], labels + more[1], fontsize=8, loc="center right")
        ax.set_title(panel_title)
        ax.set_xlabel("environment steps (thousands)")
        ax.grid(alpha=0.3)
        if len(ax.get_legend_handles_labels()[0]) > 1 and not (losses and warm_rows):
            ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    tmp = out.with_name(out.stem + ".tmp.png")
    fig.savefig(tmp, dpi=110, metadata=png_metadata(provenance()))
    plt.close(fig)
    os.replace(tmp, out)
