"""The sweep command (agents/sweep/): the sweep file's checks, its grid and tasks, the CLI on a
tiny grid (tidy CSV, summary, figure, sweep.json), bad input (exit 2) and a controller that
fails mid-sweep (exit 1, completed episodes kept and marked incomplete)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import pytest
import yaml

from agents.evaluate.settings import InputError
from agents.sweep import load_sweep, parse_sweep
from agents.sweep.cli import main, validate
from agents.sweep.spec import SWEEP_DIR

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # controllers given by import path, as in test_evaluate
    sys.path.insert(0, str(ROOT))

BASE = {"agents": ["random", "fcfs"], "configs": ["paper"],
        "grid": {"uncertainty.wind_gust_prob": [0.0, 0.3]}, "episodes": 2}


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_grid_points_and_tasks():
    spec = parse_sweep({**BASE, "grid": {"a.x": [1, 2, 3], "b.y": ["u", "v"]},
                        "set": {"c.z": 5}}, "s", "test")
    points = spec.points()
    assert len(points) == 6 and points[0] == (("a.x", 1), ("b.y", "u"))
    assert points[1] == (("a.x", 1), ("b.y", "v"))  # the first key varies slowest
    tasks = spec.tasks()
    assert len(tasks) == 2 * 1 * 6 * 2
    assert tasks[0].overrides == (("c.z", 5), ("a.x", 1), ("b.y", "u"))
    assert [t.seed for t in tasks[:2]] == [1_000_000, 1_000_001]  # the same days at every point
    assert {t.seed for t in tasks} == {1_000_000, 1_000_001}


@pytest.mark.parametrize("change, message", [
    ({"colour": 1}, "colour: unknown key"),
    ({"grid": {}}, "grid: expected a mapping"),
    ({"grid": {"uncertainty.wind_gust_prob": [0.1, 0.1]}}, "a value is listed twice"),
    ({"grid": {"uncertainty.wind_gust_prob": [[0.1]]}}, "expected a non-empty list of numbers"),
    ({"set": {"uncertainty.wind_gust_prob": 0.1}}, "both swept (grid) and fixed (set)"),
    ({"metrics": ["reward"]}, "'reward' is not a metric"),
    ({"seeds": "10:20"}, "reaches into the training seeds"),
    ({"episodes": 0}, "episodes: expected an integer"),
    ({"agents": []}, "agents: expected a non-empty list"),
])
def test_bad_sweep_files_name_the_key(change, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_sweep({**BASE, **change}, "s", "sweeps/s.yaml")


@pytest.mark.parametrize("path", sorted(SWEEP_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_sweeps_load_and_validate(path):
    spec = load_sweep(path.stem)
    validate(spec)
    assert spec.grid and spec.episodes >= 20


def test_an_override_that_breaks_a_point_is_refused_before_running(tmp_path, capsys):
    code = main(["wind", "--grid", "uncertainty.wind_gust_prob=0,1.5", "--episodes", "1",
                 "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "uncertainty.wind_gust_prob=1.5" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_sweep_cli_on_a_tiny_grid_writes_the_csv_and_the_figure(tmp_path, capsys):
    spec = _write(tmp_path, {**BASE, "set": {"schedule.episode_steps": 40},
                             "metrics": ["total_reward", "stranded", "collisions"]})
    out = tmp_path / "out"
    assert main([str(spec), "--workers", "1", "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "uncertainty.wind_gust_prob" in printed and "fcfs" in printed
    rows = _rows(out / "sweep.csv")
    assert len(rows) == 2 * 1 * 2 * 2  # agents x cases x points x days
    assert list(rows[0])[:6] == ["agent", "config", "uncertainty.wind_gust_prob", "episode",
                                 "seed", "steps"]
    assert {(r["agent"], r["uncertainty.wind_gust_prob"]) for r in rows} == {
        (a, v) for a in ("random", "fcfs") for v in ("0.0", "0.3")}
    assert all(r["steps"] == "40" for r in rows)
    summary = _rows(out / "summary.csv")
    reward = [r for r in summary if r["metric"] == "total_reward"]
    assert len(reward) == 4 and all(r["n"] == "2" for r in reward)
    for r in reward:
        assert float(r["ci_low"]) <= float(r["mean"]) <= float(r["ci_high"])
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["complete"] and doc["episodes_done"] == 8 and doc["backend"] == "local: this process"
    assert doc["spec"]["grid"] == {"uncertainty.wind_gust_prob": [0.0, 0.3]}


def test_a_controller_failing_mid_sweep_keeps_the_completed_episodes(tmp_path, capsys):
    from tests.evaluation.test_evaluate import STEPS, IllegalAfterK

    IllegalAfterK.calls = 0
    spec = _write(tmp_path, {**BASE, "agents": ["tests.evaluation.test_evaluate:IllegalAfterK"],
                             "set": {"schedule.episode_steps": STEPS}})
    out = tmp_path / "out"
    assert main([str(spec), "--workers", "1", "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "the sweep is incomplete: 1 of 4 episodes" in err
    assert len(_rows(out / "sweep.csv")) == 1
    assert not (out / "sweep.png").exists()
    assert json.loads((out / "sweep.json").read_text())["complete"] is False
