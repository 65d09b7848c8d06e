"""The evaluation in the community's formats: ``marl_eval.json`` has MARL-eval's raw-data layout
(environment, task, algorithm, run, logging step; lists of values; the same runs for every
algorithm of a task), holds every day's value of each metric, and reads back with MARL-eval's
own pipeline where that library installs."""

import csv
import json
import math

import pytest

from agents.evaluate.cli import main as evaluate
from agents.evaluate.interchange import ENVIRONMENT


def check_marl_eval_layout(data: dict) -> None:
    """The structural rules MARL-eval's README states for raw experiment data."""
    assert set(data) == {ENVIRONMENT}
    for task, algorithms in data[ENVIRONMENT].items():
        runs = {algo: set(r) for algo, r in algorithms.items()}
        assert len({frozenset(r) for r in runs.values()}) == 1, f"{task}: algorithms differ in runs"
        for algo, by_run in algorithms.items():
            for run, steps in by_run.items():
                assert "absolute_metrics" in steps and any(k.startswith("step_") for k in steps)
                for step, values in steps.items():
                    if step.startswith("step_"):
                        assert isinstance(values["step_count"], int)
                    for metric, numbers in values.items():
                        if metric == "step_count":
                            continue
                        assert isinstance(numbers, list) and numbers
                        assert all(isinstance(x, float) and math.isfinite(x) for x in numbers)


def test_marl_eval_json_holds_every_day_of_every_agent_and_case(tmp_path):
    out = tmp_path / "run"
    assert evaluate(["--agents", "random", "dispatcher", "--configs", "paper", "paper_uncertain",
                     "--episodes", "3", "--set", "schedule.episode_steps=60", "--workers", "1",
                     "--no-progress", "--out", str(out)]) == 0
    data = json.loads((out / "marl_eval.json").read_text())
    check_marl_eval_layout(data)
    with (out / "episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    tasks = data[ENVIRONMENT]
    assert set(tasks) == {"paper", "paper_uncertain"}
    for row in rows:
        run = tasks[row["config"]][row["agent"]][f"seed_{row['seed']}"]
        assert run["step_0"]["step_count"] == int(row["steps"])
        for metric in ("total_reward", "vehicles_lost", "contacts", "collisions"):
            assert run["absolute_metrics"][metric] == [pytest.approx(float(row[metric]), rel=1e-9)]


def test_a_metric_undefined_on_a_day_is_left_out_of_its_case(tmp_path):
    out = tmp_path / "run"
    assert evaluate(["--agents", "random", "--configs", "paper", "--episodes", "2",
                     "--set", "schedule.episode_steps=40", "--set", "fleet_size=1",
                     "--workers", "1", "--no-progress", "--out", str(out)]) == 0
    data = json.loads((out / "marl_eval.json").read_text())  # strict JSON: no NaN in it
    run = next(iter(data[ENVIRONMENT]["paper"]["random"].values()))
    assert "min_separation_m" not in run["absolute_metrics"]
    assert "total_reward" in run["absolute_metrics"]


def test_marl_eval_reads_it_back_where_it_installs(tmp_path):
    pipeline = pytest.importorskip(
        "marl_eval.utils.data_processing_utils",
        reason="id-marl-eval is not installed (its release pins pandas 1.4.4, which does not "
               "install beside this project's pandas); the layout is checked above")
    out = tmp_path / "run"
    assert evaluate(["--agents", "random", "dispatcher", "--configs", "paper", "--episodes", "3",
                     "--set", "schedule.episode_steps=40", "--workers", "1", "--no-progress",
                     "--out", str(out)]) == 0
    raw = json.loads((out / "marl_eval.json").read_text())
    processed = pipeline.data_process_pipeline(raw_data=raw, metrics_to_normalize=[])
    assert ENVIRONMENT in {str(k).lower() for k in processed}
