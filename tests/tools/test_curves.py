"""The curves command (python -m agents.curves, make curves) on a tiny budget: short days so
that training days end within two iterations, two seeds, a baseline on two validation days."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from agents.curves.cli import main
from agents.curves.outputs import iqm, iqm_ci


def _write_configs(tmp_path):
    env = tmp_path / "short_day.yaml"
    env.write_text("base: paper\nname: short_day\nschedule:\n  episode_steps: 8\n")
    train = tmp_path / "tiny.yaml"
    train.write_text(
        f"mode: multi_agent\nrows: turns\ncritic: state\nenv_config: {env}\n"
        "num_envs: 2\nnum_steps_per_env: 8\niterations: 5\nsave_interval: 1\n"
        "reward_scale: 0.05\npretrain:\n  days: 0\nmodel:\n  hidden: 8\n  hidden_dims: [8]\n"
        "evaluation:\n  episodes: 0\n")
    return train


def test_curves_command_writes_one_row_per_seed_and_iteration_and_the_figure(tmp_path, capsys):
    train = _write_configs(tmp_path)
    out = tmp_path / "out"
    code = main(["--configs", str(train), "--seeds", "2", "--iterations", "2", "--workers", "1",
                 "--baselines", "fcfs", "--baseline-episodes", "2", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    with open(out / "curves.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["config"], r["seed"], r["iteration"]) for r in rows] == [
        ("tiny", "0", "0"), ("tiny", "0", "1"), ("tiny", "1", "0"), ("tiny", "1", "1")]
    assert all(r["env_steps"] == str(16 * (int(r["iteration"]) + 1)) for r in rows)
    assert all(np.isfinite(float(r["total_reward"])) for r in rows)  # a day ends every iteration
    # The two seeds learn different things from different days.
    assert rows[0]["total_reward"] != rows[2]["total_reward"]
    with open(out / "summary.csv") as fh:
        summary = [r for r in csv.DictReader(fh) if r["metric"] == "total_reward"]
    assert [r["iteration"] for r in summary] == ["0", "1"]
    for r in summary:
        values = [float(x["total_reward"]) for x in rows if x["iteration"] == r["iteration"]]
        assert float(r["mean"]) == pytest.approx(np.mean(values))
        assert float(r["ci_low"]) <= float(r["mean"]) <= float(r["ci_high"])
        assert r["seeds"] == "2"
    assert (out / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / "baselines.csv") as fh:
        base = [r for r in csv.DictReader(fh) if r["metric"] == "total_reward"]
    assert [(b["agent"], b["scenarios"], b["days"]) for b in base] == [("fcfs", str(tmp_path / "short_day.yaml"), "2")]
    meta = json.loads((out / "curves.json").read_text())
    assert meta["complete"] and meta["seeds"] == [0, 1]
    assert meta["baseline_days"] == "validation seeds 800000:800002"
    assert meta["configs"]["tiny"]["iterations"] == 2
    assert [(r["config"], r["seed"]) for r in meta["runs"]] == [("tiny", 0), ("tiny", 1)]
    for run in meta["runs"]:  # each run's folder holds its config, with its seed
        saved = Path(run["run_dir"]) / "train_config.yaml"
        assert f"seed: {run['seed']}" in saved.read_text()


def test_curves_command_refuses_bad_input_before_running(tmp_path, capsys):
    train = _write_configs(tmp_path)
    assert main(["--configs", str(train), "--seeds", "0", "--out", str(tmp_path / "o")]) == 2
    assert "--seeds must be >= 1" in capsys.readouterr().err
    assert main(["--configs", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "o")]) == 2
    assert "missing.yaml" in capsys.readouterr().err
    assert main(["--configs", str(train), "--baselines", "nobody", "--out", str(tmp_path / "o")]) == 2
    assert "nobody" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_iqm_drops_the_lowest_and_highest_quarter():
    assert iqm(np.array([0.0, 1.0, 2.0, 3.0, 100.0, -100.0, 1.5, 2.5])) == pytest.approx(1.75)
    assert iqm(np.array([1.0, 2.0, 9.0])) == pytest.approx(4.0)  # fewer than 4: the mean
    low, high = iqm_ci([1.0, 2.0, 3.0, 4.0, 5.0], resamples=200)
    assert 1.0 <= low <= 3.0 <= high <= 5.0


def test_baseline_lines_say_which_days_scored_them():
    from agents.curves.outputs import baseline_label

    base = {"agent": "fcfs", "scenarios": "paper, wide"}
    assert baseline_label(base, (900000, 900010)).endswith(
        "(paper, wide, validation days 900000-900009)")
    assert "validation" not in baseline_label(base, None)


def _numbers(path):
    with open(path) as fh:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def test_resume_goes_on_from_the_last_checkpoint_and_may_extend_the_budget(tmp_path, capsys):
    train = _write_configs(tmp_path)
    out = tmp_path / "out"
    base = ["--configs", str(train), "--workers", "1", "--baseline-episodes", "0", "--out", str(out)]
    assert main([*base, "--seeds", "1", "--iterations", "2"]) == 0, capsys.readouterr().err
    first = _numbers(out / "runs" / "tiny_seed0" / "curves.csv")
    # Seed 0 is extended from 2 to 3 iterations; seed 1, with no folder yet, starts afresh.
    assert main([*base, "--seeds", "2", "--iterations", "3", "--resume"]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "resuming tiny seed 0" in printed and "resuming tiny seed 1" not in printed
    with open(out / "curves.csv") as fh:
        rows = [(r["seed"], r["iteration"]) for r in csv.DictReader(fh)]
    assert rows == [("0", "0"), ("0", "1"), ("0", "2"), ("1", "0"), ("1", "1"), ("1", "2")]
    again = _numbers(out / "runs" / "tiny_seed0" / "curves.csv")
    assert len(first) == 2 and again[:2] == first  # the iterations trained before are kept
    assert (out / "runs" / "tiny_seed0" / "model_2.pt").exists()
    assert "iterations: 3" in (out / "runs" / "tiny_seed0" / "train_config.yaml").read_text()
    meta = json.loads((out / "curves.json").read_text())
    assert [(r["seed"], r["resumed_at"]) for r in meta["runs"]] == [(0, 2), (1, None)]


def test_resume_refuses_a_run_of_another_config_or_a_shorter_budget(tmp_path, capsys):
    train = _write_configs(tmp_path)
    out = tmp_path / "out"
    base = ["--configs", str(train), "--seeds", "1", "--workers", "1", "--baseline-episodes", "0",
            "--out", str(out)]
    assert main([*base, "--iterations", "2"]) == 0, capsys.readouterr().err
    saved = (out / "runs" / "tiny_seed0" / "curves.csv").read_text()
    assert main([*base, "--iterations", "1", "--resume"]) == 2
    assert "would cut it short" in capsys.readouterr().err
    other = tmp_path / "tiny.yaml"
    other.write_text(other.read_text().replace("reward_scale: 0.05", "reward_scale: 0.1"))
    assert main([*base, "--iterations", "2", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "started with another config" in err and "reward_scale" in err
    assert (out / "runs" / "tiny_seed0" / "curves.csv").read_text() == saved  # nothing touched


def test_summary_aligns_seeds_whose_days_end_on_other_iterations():
    """A resumed seed's days end on other iterations: each point still counts every seed, at
    its latest finished day, and a seed counts only up to the last iteration its run trained."""
    from agents.curves.outputs import CurvesResult, summary_rows

    def run(days, trained):
        rows = {it: {"iteration": it, "env_steps": 10 * (it + 1)} for it in range(trained + 1)}
        for it, v in days:
            rows[it].update(total_reward=v, stranded=0.0, collisions=0.0)
        return {"rows": list(rows.values())}

    result = CurvesResult(labels=["a"], configs={"a": {}}, seeds=[0, 1, 2])
    result.runs[("a", 0)] = run([(2, 1.0), (5, 2.0), (8, 3.0)], trained=9)
    result.runs[("a", 1)] = run([(2, 10.0), (6, 20.0), (9, 30.0)], trained=9)
    result.runs[("a", 2)] = run([(2, 100.0), (5, 200.0)], trained=5)  # stopped early
    rows = {r["iteration"]: r for r in summary_rows(result, resamples=50)
            if r["metric"] == "total_reward"}
    assert sorted(rows) == [2, 5, 6, 8, 9]
    assert [rows[i]["seeds"] for i in (2, 5, 6, 8, 9)] == [3, 3, 2, 2, 2]
    assert rows[2]["mean"] == pytest.approx(37.0)
    assert rows[5]["mean"] == pytest.approx((2.0 + 10.0 + 200.0) / 3)  # seed 1 as of iteration 2
    assert rows[6]["mean"] == pytest.approx(11.0)  # seed 2 trained no iteration after 5
    assert rows[8]["mean"] == pytest.approx(11.5) and rows[8]["env_steps"] == 90
    assert rows[9]["mean"] == pytest.approx(16.5)  # seed 0 as of iteration 8: both end at 9
