"""What a run's checkpoints carry and where they are: the metadata every checkpoint holds (the
configs, the feature schema its weights depend on), the newest complete one of a run, and the
slim copy of one that ships (``agents/checkpoints/gcn_default.pt``)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from agents.common.files import write_torch_atomic
from agents.gcn.features import feature_names
from agents.training.config import TrainConfig, scenario_configs
from marl_vertiport.config import to_dict

CHECKPOINT_FORMAT = 2  # 2: size-agnostic models, the feature schema in the metadata
#: The warm start's progress in a run folder (agents/training/imitation.py).
WARM_STATE = "warmstart_state.pt"


def checkpoint_infos(cfg: TrainConfig, env_cfg) -> dict[str, Any]:
    """Run metadata stored in every checkpoint: the configs and the actor's feature schema
    (the column names its weights depend on; layout and fleet sizes do not matter)."""
    return {"marl_vertiport": {"format": CHECKPOINT_FORMAT, "mode": cfg.mode,
                               "train_config": to_dict(cfg), "env_config": to_dict(env_cfg),
                               "scenarios": [c.name for c in scenario_configs(cfg)],
                               "feature_schema": feature_names("observation")}}


def ppo_checkpoints(run_dir: Path) -> list[Path]:
    """The complete PPO checkpoints ``model_<iteration>.pt`` of a run folder, by iteration (temp
    files and the warm start's ``model_warmstart.pt``, ``model_fit<k>.pt`` ignored)."""
    found = []
    for path in run_dir.glob("model_*.pt"):
        m = re.fullmatch(r"model_(\d+)\.pt", path.name)
        if m:
            found.append((int(m.group(1)), path))
    return [path for _, path in sorted(found)]


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The complete checkpoint with the highest iteration in a run folder (temp files ignored)."""
    found = ppo_checkpoints(run_dir)
    return found[-1] if found else None


#: What a shipped checkpoint keeps of a run's: the weights, the iteration and the metadata.
SHIPPED_KEYS = ("actor_state_dict", "critic_state_dict", "iter", "infos")


def slim_checkpoint(source: Path, target: Path) -> None:
    """Write ``source`` (a run's ``model_<it>.pt``) to ``target`` without what only resuming a
    run needs (the optimizer's state): the file that ships, with the same weights and metadata.
    ``python -c "from agents.training.checkpoints import slim_checkpoint as s;
    s('runs/train/<run>/model_59.pt', 'agents/checkpoints/gcn_default.pt')"``."""
    import torch

    data = torch.load(Path(source), map_location="cpu", weights_only=True)
    missing = [k for k in SHIPPED_KEYS if k not in data]
    if missing:
        raise ValueError(f"{source}: not a training checkpoint (no {', '.join(missing)})")
    write_torch_atomic(Path(target), {k: data[k] for k in SHIPPED_KEYS})
