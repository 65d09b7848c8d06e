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
    """One training run: the label of its config, its resolved config (with ``seed``), its
    folder, and whether it continues the run already in that folder (``resume``)."""

    label: str
    config: dict[str, Any]
    run_dir: str
    resume: bool = False

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
    process), or with ``task.resume`` continue it from its folder's last checkpoint; returns
    ``{"rows": curves.csv rows, "seconds": wall time of this call, "checkpoint": path,
    "resumed_at": the first iteration trained by this call, or None for a new run}``."""
    import yaml

    from agents.common.files import write_atomic
    from agents.execution import LocalBackend
    from agents.training.checkpoints import latest_checkpoint
    from agents.training.config import TrainConfig
    from agents.training.curves import read_curves
    from agents.training.pipeline import train
    from marl_vertiport.config import build_dataclass, to_dict

    cfg = build_dataclass(TrainConfig, task.config)
    run_dir = Path(task.run_dir)
    start = time.perf_counter()
    resumed_at = None
    if task.resume:
        # train() goes on after the last checkpoint, model_<it>.pt.
        resumed_at = int(latest_checkpoint(run_dir).stem.split("_")[1]) + 1
        # The folder's config says the budget it now runs to (a resumed run may extend it).
        write_atomic(run_dir / "train_config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
    final = train(cfg, run_dir, resume=task.resume, evaluate=False,
                  log=_progress_log(f"{task.label} seed {task.seed}"), backend=LocalBackend(1))
    return {"rows": read_curves(run_dir / "curves.csv"), "seconds": time.perf_counter() - start,
            "checkpoint": str(final) if final is not None else "", "resumed_at": resumed_at}


def resumable(run_dir: Path, config: dict[str, Any]) -> bool:
    """Whether ``run_dir`` holds a run of ``config`` to continue: ``False`` where it holds no
    checkpoint yet (a new run starts there). Raises ``ConfigError`` where its run was started
    with another config: every key must match but ``iterations``, which may only grow (a
    finished run is extended to the new budget)."""
    import yaml

    from agents.training.checkpoints import latest_checkpoint
    from agents.training.config import TrainConfig
    from marl_vertiport.config import ConfigError, build_dataclass, to_dict

    if latest_checkpoint(run_dir) is None:
        return False
    saved_path = run_dir / "train_config.yaml"
    try:
        saved = yaml.safe_load(saved_path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"--resume: {saved_path}: cannot read the run's config ({exc})") from exc
    if not isinstance(saved, dict):
        raise ConfigError(f"--resume: {saved_path}: not a train config")
    # The config as train() saves it (validated, through YAML), to compare like with like.
    config = yaml.safe_load(yaml.safe_dump(to_dict(build_dataclass(TrainConfig, config)),
                                           sort_keys=False))
    differ = sorted(k for k in set(saved) | set(config)
                    if k != "iterations" and saved.get(k) != config.get(k))
    if differ:
        raise ConfigError(f"--resume: {run_dir} was started with another config (it differs in "
                          f"{', '.join(differ)}); use another --out, or the same config")
    if int(config["iterations"]) < int(saved.get("iterations", 0)):
        raise ConfigError(f"--resume: {run_dir} was started for {saved['iterations']} iterations; "
                          f"--iterations {config['iterations']} would cut it short")
    return True


def baseline_seeds(episodes: int) -> tuple[int, int]:
    """``(first, stop)``: the validation days the baselines are scored on (never test days)."""
    return VALIDATION_SEED_BASE, VALIDATION_SEED_BASE + episodes
