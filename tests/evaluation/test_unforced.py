"""Unforced losses in the evaluation's own summary (agents/evaluate/unforced.py): per agent and
case, over the days a reference agent played, from the per-day definition of
agents/evaluate/paired.py; in summary.csv, results.json, the console table and the report, right
after the vehicles lost, and never in episodes.csv."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import pytest

from agents import evaluate as ev
from agents.evaluate.settings import EpisodeRecord, EpisodeTask, EvalSettings, Evaluation
from agents.evaluate.stats import summarize
from agents.evaluate.tables import format_table, summary_metrics
from agents.evaluate.unforced import reference_agents, unforced_rows, with_unforced

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # the test controllers load by import path
    sys.path.insert(0, str(ROOT))

SEEDS = (800000, 800001, 800002)
# Vehicles lost (air, ground) per agent, case and day.
LOST = {
    "random": {"paper": [(1, 2), (0, 0), (2, 0)], "twin": [(0, 3), (1, 1), (0, 0)]},
    "dispatcher": {"paper": [(0, 1), (0, 0), (1, 0)], "twin": [(0, 1), (0, 2), (0, 0)]},
    "planner": {"paper": [(0, 0), (0, 1), (0, 1)], "twin": [(0, 2), (0, 1), (1, 0)]},
    "guard": {"paper": [(0, 0), (0, 0), (0, 0)], "twin": [(0, 1), (0, 0), (0, 0)]},
}


def records(agents=("random", "dispatcher", "planner"), configs=("paper", "twin")):
    out = []
    for agent in agents:
        for config in configs:
            for k, seed in enumerate(SEEDS):
                air, ground = LOST[agent][config][k]
                metrics = {"steps": 1440, "total_reward": 10.0 * k, "stranded_air": air,
                           "stranded_ground": ground, "stranded": air + ground,
                           "vehicles_lost": air + ground, "service_min_lost": 0.0}
                out.append(EpisodeRecord(EpisodeTask(agent, config, k, seed), metrics))
    return out


def settings(agents=("random", "dispatcher", "planner"), configs=("paper", "twin")):
    return EvalSettings(agents=agents, configs=configs, episodes=len(SEEDS), first_seed=SEEDS[0],
                        bootstrap=200)


def test_unforced_losses_are_the_losses_beyond_the_best_reference_agent_of_the_day():
    s = settings()
    assert reference_agents(s) == ["dispatcher", "planner"]
    rows = {(r["agent"], r["config"]): r for r in unforced_rows(records(), s)}
    # random on paper: lost 3, 0, 2; the references' fewest 0, 0, 1 -> 3, 0, 1
    assert rows["random", "paper"]["mean"] == pytest.approx(4 / 3)
    assert rows["random", "paper"]["n"] == 3
    # on twin: lost 3, 2, 0 against 1, 1, 0 -> 2, 1, 0
    assert rows["random", "twin"]["mean"] == pytest.approx(1.0)
    # the dispatcher: 1, 0, 1 against 0, 0, 1 -> 1, 0, 0; the planner: 0, 1, 1 against 0, 0, 1
    assert rows["dispatcher", "paper"]["mean"] == pytest.approx(1 / 3)
    assert rows["planner", "paper"]["mean"] == pytest.approx(1 / 3)
    assert all(r["metric"] == "unforced_losses" for r in rows.values())
    assert len(rows) == 6


def test_the_guard_is_a_reference_agent_too():
    agents = ("random", "dispatcher", "planner", "guard")
    s = settings(agents=agents)
    assert reference_agents(s) == ["dispatcher", "planner", "guard"]
    rows = {(r["agent"], r["config"]): r for r in unforced_rows(records(agents), s)}
    # the guard loses nothing on paper: every loss of the others there is unforced
    assert rows["dispatcher", "paper"]["mean"] == pytest.approx(2 / 3)
    assert rows["random", "paper"]["mean"] == pytest.approx(5 / 3)
    # on twin the fewest are 1, 0, 0: the dispatcher's 1, 2, 0 -> 0, 2, 0
    assert rows["dispatcher", "twin"]["mean"] == pytest.approx(2 / 3)
    assert rows["guard", "twin"]["mean"] == 0.0


def test_without_a_reference_day_there_is_no_row():
    s = settings(agents=("random",))
    assert reference_agents(s) == [] and unforced_rows(records(("random",)), s) == []
    # only the days a reference agent played count: the dispatcher played paper alone
    both = records(("random",)) + records(("dispatcher",), ("paper",))
    rows = unforced_rows(both, settings(agents=("random", "dispatcher")))
    assert {(r["agent"], r["config"]) for r in rows} == {("random", "paper"),
                                                         ("dispatcher", "paper")}


def test_the_row_follows_the_vehicles_lost_and_the_table_says_n_a_where_it_has_none():
    s = settings(agents=("random", "dispatcher"))
    recs = records(("random",)) + records(("dispatcher",), ("paper",))
    metrics = ["steps", "total_reward", "stranded_air", "stranded_ground", "stranded",
               "vehicles_lost", "service_min_lost"]
    summary = with_unforced(summarize(recs, s, metrics), unforced_rows(recs, s))
    names = [(r["agent"], r["config"], r["metric"]) for r in summary]
    at = names.index(("random", "paper", "vehicles_lost"))
    assert names[at + 1] == ("random", "paper", "unforced_losses")
    assert ("random", "twin", "unforced_losses") not in names
    evaluation = Evaluation(s, recs, {}, metrics, summary)
    assert summary_metrics(evaluation) == [*metrics[:6], "unforced_losses", "service_min_lost"]
    table = format_table(evaluation)
    twin = table.split("\n\n")[1]
    assert "unforced" in twin.splitlines()[1] and "n/a" in twin.splitlines()[3]
    assert "n/a" not in table.split("\n\n")[0]


def test_the_evaluation_reports_them_and_keeps_them_out_of_the_episodes(tmp_path, capsys):
    out, report = tmp_path / "out", tmp_path / "report.md"
    argv = ["--agents", "dispatcher", "tests.evaluation.test_evaluate:FirstLegal", "--configs",
            "paper", "--episodes", "2", "--set", "schedule.episode_steps=40", "--no-progress",
            "--out", str(out), "--report", str(report)]
    assert ev.main(argv) == 0
    assert "unforced" in capsys.readouterr().out.splitlines()[1]
    with (out / "episodes.csv").open(newline="") as fh:
        header = next(csv.reader(fh))
    assert "unforced_losses" not in header
    with (out / "summary.csv").open(newline="") as fh:
        summary = list(csv.DictReader(fh))
    metrics = [r["metric"] for r in summary if r["agent"] == "dispatcher"]
    assert metrics[metrics.index("vehicles_lost") + 1] == "unforced_losses"
    dispatcher = [r for r in summary if r["metric"] == "unforced_losses"]
    assert len(dispatcher) == 2 and dispatcher[0]["mean"] == "0.0"  # the reference itself
    doc = json.loads((out / "results.json").read_text())
    assert doc["unforced_reference"] == ["dispatcher"]
    assert all("unforced_losses" not in e["metrics"] for e in doc["episodes"])
    assert "| unforced losses/day |" in report.read_text()
