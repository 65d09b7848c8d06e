"""Training seeds as tasks of the execution layer, and the baselines' days.

A task trains one (train config, seed) into its own run folder and returns the rows of its
``curves.csv``: what a run learned depends only on its config and seed, never on the backend
or the process that ran it. On a Ray cluster the run folder (checkpoints, logs) stays on the
node that ran it; its curve comes back to the driver.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.common.seeds import VALIDATION_SEED_BASE

#: Every how many PPO iterations a run's progress line is printed (and its first and last).
PROGRESS_EVERY = 10
_ITERATION = re.compile(r"it\s+(\d+)/(\d+)")


@dataclass(frozen=True)
class SeedTask:
    """One training run: the label of its config, its resolved config (with ``seed``) and
    its folder."""

    label: str
    config: dict[str, Any]
    run_dir: str

    @property
    def seed(self) -> int:
        return int(self.config["seed"])


def _progress_log(prefix: str):
    """A log that keeps every line but the per-iteration ones, of which it keeps one in
    :data:`PROGRESS_EVERY` (and the last)."""

    def log(message: str) -> None:
        m = _ITERATION.match(message)
        if m and int(m.group(1)) % PROGRESS_EVERY and m.group(1) != m.group(2):
            return
        print(f"[{prefix}] {message}", flush=True)

    return log


def train_seed(task: SeedTask) -> dict[str, Any]:
    """Train one seed (no end-of-run evaluation; the warm start, if any, runs in this
    process); returns ``{"rows": curves.csv rows, "seconds": wall time, "checkpoint": path}``."""
    from agents.execution import LocalBackend
    from agents.training.config import TrainConfig
    from agents.training.curves import read_curves
    from agents.training.pipeline import train
    from marl_vertiport.config import build_dataclass

    cfg = build_dataclass(TrainConfig, task.config)
    run_dir = Path(task.run_dir)
    start = time.perf_counter()
    final = train(cfg, run_dir, evaluate=False, log=_progress_log(f"{task.label} seed {task.seed}"),
                  backend=LocalBackend(1))
    return {"rows": read_curves(run_dir / "curves.csv"), "seconds": time.perf_counter() - start,
            "checkpoint": str(final) if final is not None else ""}


def baseline_seeds(episodes: int) -> tuple[int, int]:
    """``(first, stop)``: the validation days the baselines are scored on (never test days)."""
    return VALIDATION_SEED_BASE, VALIDATION_SEED_BASE + episodes
