"""Same machine, same config and seed: the same checkpoints, whatever runs the tasks.

A tiny pipeline with every stage of the default (warm start by the look-ahead planner across two
scenarios, day starts with noise and low batteries, the ensemble stage, a critic warm-up, PPO)
runs in fresh processes, once with its days in the training process itself and once on a pool of
two worker processes (and on Ray where the extra is installed); every file it writes must be the
same, byte for byte and tensor for tensor (docs/training.md, "Reproducibility")."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml

ROOT = Path(__file__).resolve().parents[2]

TINY = {
    "base": str(ROOT / "configs" / "train" / "default.yaml"),
    "scenarios": ["paper", "small"],
    "num_envs": 2, "num_steps_per_env": 8, "iterations": 3, "save_interval": 1,
    "critic_warmup_iterations": 1,
    "pretrain": {"days": 2, "day_steps": 30, "starts": 2, "start_steps": 10,
                 "low_battery_starts": 1, "planner_horizon": 4, "epochs": 2, "batch_size": 64},
    "ensemble": {"fits": 1, "days": 2, "epochs": 1},
    "evaluation": {"episodes": 0},
}


def train_run(config: Path, run_dir: Path, *args: str) -> None:
    """``python -m agents.train`` in a process of its own."""
    out = subprocess.run([sys.executable, "-m", "agents.train", "--config", str(config),
                          "--run-dir", str(run_dir), "--no-eval", *args],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]


def tensors(value, path=""):
    """Every tensor in a checkpoint's content, by its path of keys."""
    if isinstance(value, torch.Tensor):
        yield path, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from tensors(v, f"{path}/{k}")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            yield from tensors(v, f"{path}/{i}")


def assert_same_run(a: Path, b: Path) -> None:
    files = sorted(p.name for p in a.iterdir() if p.suffix in (".pt", ".csv", ".yaml"))
    assert files == sorted(p.name for p in b.iterdir() if p.suffix in (".pt", ".csv", ".yaml"))
    checkpoints = [f for f in files if f.endswith(".pt")]
    # Every stage wrote its file: the warm start, the refit, the distilled actor, each iteration.
    assert {"warmstart_state.pt", "model_warmstart.pt", "model_refit1.pt", "model_distilled.pt",
            "model_0.pt", "model_1.pt", "model_2.pt"} <= set(checkpoints)
    for name in checkpoints:
        da = torch.load(a / name, weights_only=True)
        db = torch.load(b / name, weights_only=True)
        ta, tb = dict(tensors(da)), dict(tensors(db))
        assert ta.keys() == tb.keys(), name
        differ = [k for k in ta if not torch.equal(ta[k], tb[k])]
        assert not differ, f"{name}: tensors differ: {differ[:5]}"
        assert (a / name).read_bytes() == (b / name).read_bytes(), f"{name}: bytes differ"
    for name in files:
        if name.endswith(".csv"):  # curves.csv holds the speed in steps per second: not that
            rows_a = list(csv.DictReader((a / name).open()))
            rows_b = list(csv.DictReader((b / name).open()))
            drop = lambda row: {k: v for k, v in row.items() if k != "steps_per_s"}  # noqa: E731
            assert [drop(r) for r in rows_a] == [drop(r) for r in rows_b], name
        elif name.endswith(".yaml"):
            assert (a / name).read_text() == (b / name).read_text(), name


@pytest.mark.slow
def test_the_pipeline_gives_the_same_checkpoints_on_one_worker_and_on_two(tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    train_run(config, tmp_path / "one", "--workers", "1")
    train_run(config, tmp_path / "two", "--workers", "2")
    assert_same_run(tmp_path / "one", tmp_path / "two")


@pytest.mark.slow
def test_the_pipeline_gives_the_same_checkpoints_on_ray(tmp_path):
    pytest.importorskip("ray", reason="the ray extra: pip install -e '.[ray]'")
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    train_run(config, tmp_path / "one", "--workers", "1")
    train_run(config, tmp_path / "ray", "--backend", "ray", "--workers", "2")
    assert_same_run(tmp_path / "one", tmp_path / "ray")
