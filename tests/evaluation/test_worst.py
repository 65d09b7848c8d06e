"""The worst-day pick (agents/evaluate/worst.py), its section of the report, and the replay that
renders it with its decision log (agents/render/worst_day.py)."""

import csv
import json

import pytest

from agents.evaluate.cli import main as evaluate
from agents.evaluate.worst import worst_days
from agents.render import worst_day


def _row(agent, config, episode, reward, lost=0, contacts=0, flat=False):
    metrics = {"total_reward": reward, "stranded": lost, "contacts": contacts}
    base = {"agent": agent, "config": config, "episode": episode, "seed": 1000 + episode}
    return {**base, **metrics} if flat else {**base, "metrics": metrics}


@pytest.mark.parametrize("flat", [False, True])
def test_first_loss_or_contact_else_lowest_reward(flat):
    rows = [_row("a", "paper", 2, -50.0, lost=1, flat=flat), _row("a", "paper", 0, 10.0, flat=flat),
            _row("a", "paper", 1, 5.0, contacts=1, flat=flat),
            _row("b", "paper", 0, 3.0, flat=flat), _row("b", "paper", 1, -7.0, flat=flat),
            _row("b", "paper", 2, -7.0, flat=flat)]
    a, b = worst_days(rows)
    assert (a.agent, a.seed, a.reason, a.contacts) == ("a", 1001, "first loss or contact", 1)
    assert (b.agent, b.seed, b.reason, b.total_reward) == ("b", 1001, "lowest reward", -7.0)


def test_event_window_and_lowest_reward_window():
    rows = [{"step": k, "reward": 1.0, "events": ""} for k in range(10)]
    rows[6]["events"] = "take-off; vehicle lost: evtol_2"
    assert worst_day.event_step(rows) == 6
    rows[3]["reward"] = rows[4]["reward"] = -5.0
    assert worst_day.lowest_reward_window(rows, 2) == 3
    assert worst_day.lowest_reward_window(rows, 20) == 0


def test_an_evaluation_lists_its_worst_days_and_the_replay_renders_them(tmp_path, capsys):
    out = tmp_path / "run"
    assert evaluate(["--agents", "random", "dispatcher", "--configs", "paper", "--episodes", "2",
                     "--workers", "1", "--no-progress", "--set", "schedule.episode_steps=150",
                     "--out", str(out), "--report", str(out / "report.md")]) == 0
    report = (out / "report.md").read_text()
    assert "## Worst days" in report and "python -m agents.render.worst_day" in report
    doc = json.loads((out / "results.json").read_text())
    assert doc["settings"]["rules"] == 1
    with (out / "episodes.csv").open(newline="") as fh:
        picks = worst_days(list(csv.DictReader(fh)))  # the CSV holds every scalar metric
    assert [p.agent for p in picks] == ["random", "dispatcher"]
    assert worst_day.main([str(out), "--size", "320x240", "--window-min", "20",
                           "--before-min", "15", "--after-min", "5", "--no-progress"]) == 0
    folder = out / "worst_day"
    index = (folder / "index.md").read_text()
    for p in picks:
        stem = f"{p.agent}_paper"
        assert (folder / f"{stem}.gif").stat().st_size > 0
        log = json.loads((folder / f"{stem}.decisions.json").read_text())
        assert len(log["rows"]) == 150 and log["meta"]["seed"] == p.seed  # the whole day
        assert f"| {p.agent} | paper | {p.seed} | {p.reason} |" in index
    assert "| yes |" in index and "NO" not in index  # the replays earn the run's rewards


def test_a_folder_without_results_is_a_named_error(tmp_path, capsys):
    assert worst_day.main([str(tmp_path), "--no-progress"]) == 2
    assert "results.json not found" in capsys.readouterr().err
    (tmp_path / "results.json").write_text("{not json")
    assert worst_day.main([str(tmp_path), "--no-progress"]) == 2
    assert "is not an evaluation's results.json" in capsys.readouterr().err
