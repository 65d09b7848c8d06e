"""The evaluation command (agents/evaluate/) on tiny budgets: outputs, determinism across
worker counts and reruns, bootstrap intervals, bad input (exit 2), an agent that turns illegal
mid-run (exit 1, partial results kept), and the Markdown report."""

from __future__ import annotations

import csv
import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from agents import evaluate as ev
from agents.controllers.base import Controller
from agents.common.seeds import EVAL_SEEDS

ROOT = Path(__file__).resolve().parents[2]
# The controllers below are loaded by import path (``tests.evaluation.test_evaluate:...``),
# also in spawned workers, which inherit this process's sys.path: make sure the repository root
# is on it.
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

STEPS = 40
TINY = ["--set", f"schedule.episode_steps={STEPS}", "--no-progress"]
EPISODES = 3
AGENTS = ["random", "tests.evaluation.test_evaluate:FirstLegal"]
METRICS = ["steps", "total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
           "takeoffs", "failed_takeoffs", "landings", "mean_delay_min", "collisions",
           "avoided_conflicts", "separation_losses", "min_separation_m",
           "separation_loss_min", "trail_hold_min", "contacts", "battery_depletions",
           "stranded_air", "stranded_ground", "stranded", "vehicles_lost", "reserve_violations",
           "service_min_lost",
           "completed_trips"]


class FirstLegal(Controller):
    """Deterministic: always the lowest-numbered legal action."""

    name = "first_legal"

    def act(self, observation: dict) -> int:
        return int(np.flatnonzero(observation["action_mask"])[0])


class CrashesOnTurnThree(Controller):
    """Raises from its own code on its third decision of a day."""

    name = "crashes"

    def reset(self, seed=None) -> None:
        self.turns = 0

    def act(self, observation: dict) -> int:
        self.turns += 1
        if self.turns == 3:
            return self.turns // 0  # the crash
        return int(np.flatnonzero(observation["action_mask"])[0])


class IllegalAfterK(Controller):
    """Legal for the first ``K`` calls made in this process (counted over all instances), then
    an out-of-range action. With STEPS-step days, the first day completes and the second fails."""

    name = "illegal_after_k"
    K = STEPS + STEPS // 2
    calls = 0

    def act(self, observation: dict) -> int:
        type(self).calls += 1
        mask = observation["action_mask"]
        if type(self).calls > self.K:
            return len(mask)  # no such action
        return int(np.flatnonzero(mask)[0])


def _run(tmp: Path, *extra: str, agents=AGENTS, workers: int = 1, episodes: int = EPISODES,
         report: Path | None = None) -> int:
    argv = ["--agents", *agents, "--episodes", str(episodes), "--workers", str(workers),
            "--out", str(tmp), *TINY, *extra]
    if report is not None:
        argv += ["--report", str(report)]
    return ev.main(argv)


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    """One complete tiny run, in-process (--workers 1), with a report in a sibling folder."""
    base = tmp_path_factory.mktemp("eval")
    out, report = base / "out", base / "docs" / "results.md"
    rc = _run(out, report=report)
    return rc, out, report


def test_cli_writes_every_output(serial_run, capsys):
    rc, out, _ = serial_run
    assert rc == 0
    for name in ("episodes.csv", "summary.csv", "results.json", "case_study.png",
                 "action_distribution.png"):
        assert (out / name).is_file(), name
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]

    episodes = _rows(out / "episodes.csv")
    assert list(episodes[0]) == ["agent", "config", "episode", "seed", *METRICS]
    assert len(episodes) == len(AGENTS) * 2 * EPISODES
    keys = [(r["agent"], r["config"], int(r["episode"])) for r in episodes]
    assert keys == [(a, c, k) for a in AGENTS for c in ("paper", "paper_uncertain")
                    for k in range(EPISODES)]
    assert all(int(r["seed"]) == EVAL_SEEDS[int(r["episode"])] for r in episodes)
    assert all(int(r["steps"]) == STEPS for r in episodes)

    summary = _rows(out / "summary.csv")
    assert list(summary[0]) == ["agent", "config", "metric", "mean", "std", "ci_low", "ci_high",
                                "n"]
    assert len(summary) == len(AGENTS) * 2 * len(METRICS)
    assert all(int(r["n"]) == EPISODES for r in summary)

    doc = json.loads((out / "results.json").read_text())
    assert doc["complete"] is True and doc["error"] is None
    assert doc["settings"]["seeds"] == list(EVAL_SEEDS[:EPISODES])
    assert doc["settings"]["overrides"] == {"schedule.episode_steps": STEPS}
    assert doc["settings"]["bootstrap"]["resamples"] == 2000
    names = doc["action_names"]["paper"]
    assert names[:3] == ["stay", "takeoff", "normal_port_0"]
    assert names[-2:] == ["continue", "avoid_collision"]
    first = doc["episodes"][0]["metrics"]
    assert len(first["action_counts"]) == len(names)
    assert sum(first["action_counts"]) == STEPS
    assert set(first) == {"action_counts"}  # the scalar metrics are episodes.csv's alone
    assert len(doc["summary"]) == len(summary)
    lines = (out / "results.json").read_text().splitlines()  # an episode a line, a row a line
    assert sum(line.startswith('  {"agent"') for line in lines) == len(doc["episodes"]) + len(summary)

    for name in ("case_study.png", "action_distribution.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_summary_matches_episodes(serial_run):
    _, out, _ = serial_run
    episodes = _rows(out / "episodes.csv")
    for row in _rows(out / "summary.csv"):
        values = [float(e[row["metric"]]) for e in episodes
                  if (e["agent"], e["config"]) == (row["agent"], row["config"])]
        assert float(row["mean"]) == pytest.approx(np.mean(values))
        assert float(row["std"]) == pytest.approx(np.std(values, ddof=1))
        assert float(row["ci_low"]) <= float(row["mean"]) <= float(row["ci_high"])


def test_same_numbers_with_two_workers_and_on_rerun(serial_run, tmp_path):
    _, out, _ = serial_run
    assert _run(tmp_path / "w2", workers=2) == 0
    assert _run(tmp_path / "rerun", workers=1) == 0
    for other in (tmp_path / "w2", tmp_path / "rerun"):
        for name in ("episodes.csv", "summary.csv"):
            assert (other / name).read_bytes() == (out / name).read_bytes(), (other, name)
        a = json.loads((out / "results.json").read_text())
        b = json.loads((other / "results.json").read_text())
        for key in ("settings", "episodes", "summary", "action_names", "complete"):
            assert a[key] == b[key], key


def test_bootstrap_ci_contains_mean_and_is_reproducible():
    x = np.random.default_rng(7).exponential(3.0, size=25)
    first = ev.describe(x)
    assert first == ev.describe(x)
    assert first["ci_low"] < first["mean"] < first["ci_high"]
    assert first["std"] == pytest.approx(np.std(x, ddof=1))
    assert first["n"] == 25
    assert ev.bootstrap_ci(x, seed=1) != ev.bootstrap_ci(x, seed=0)
    narrow = ev.bootstrap_ci(x, confidence=0.5)
    assert first["ci_low"] < narrow[0] < narrow[1] < first["ci_high"]
    assert ev.describe([4.0]) == {"mean": 4.0, "std": 0.0, "ci_low": 4.0, "ci_high": 4.0, "n": 1}
    assert ev.bootstrap_ci([0.1] * 9) == (0.1, 0.1)


def test_unknown_agent_exits_2_before_running(tmp_path, capsys):
    rc = _run(tmp_path / "out", agents=["random", "no_such_agent"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "no_such_agent" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("spec, words", [
    ("tests.no_such_module:Thing", ["tests.no_such_module"]),
    ("agents.controllers.random_agent:NoSuchController", ["agents.controllers.random_agent", "NoSuchController"]),
])
def test_broken_import_path_exits_2(tmp_path, capsys, spec, words):
    rc = _run(tmp_path / "out", agents=[spec])
    err = capsys.readouterr().err
    assert rc == 2
    assert all(w in err for w in words)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("extra, word", [
    (["--set", "schedule.no_such_key=1"], "no_such_key"),
    (["--set", "episode_steps"], "KEY=VALUE"),
    (["--configs", "no_such_case"], "no_such_case"),
    (["--episodes", "0"], "--episodes"),
    (["--seeds", "5:10"], "training seeds"),
    (["--seeds", "1000010"], "START:STOP"),
    (["--seeds", "1000010:1000000"], "STOP must be greater"),
    (["--suite", "no_such_suite"], "no_such_suite"),
])
def test_bad_config_or_options_exit_2(tmp_path, capsys, extra, word):
    assert _run(tmp_path / "out", *extra) == 2
    assert word in capsys.readouterr().err


def test_module_entry_point_exit_code(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "agents.evaluate", "--agents", "nobody",
                           "--out", str(tmp_path / "out")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "nobody" in proc.stderr


def test_help_lists_every_option(capsys):
    with pytest.raises(SystemExit) as exc:
        ev.main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for option in ("--agents", "--configs", "--episodes", "--seeds", "--suite", "--workers",
                   "--out", "--report", "--set", "--bootstrap", "--bootstrap-seed", "--no-progress"):
        assert option in text


def _illegal_agent_class():
    return importlib.import_module("tests.evaluation.test_evaluate").IllegalAfterK


def test_illegal_action_exits_1_and_keeps_completed_episodes(tmp_path, capsys):
    _illegal_agent_class().calls = 0
    spec = "tests.evaluation.test_evaluate:IllegalAfterK"
    out = tmp_path / "out"
    rc = _run(out, agents=["random", spec], report=tmp_path / "report.md")
    err = capsys.readouterr().err
    assert rc == 1
    assert spec in err and "'paper'" in err and str(EVAL_SEEDS[1]) in err
    rows = _rows(out / "episodes.csv")
    # random's 6 episodes, then the failing agent's first day of case 1.
    assert [(r["agent"], r["config"], r["episode"]) for r in rows][-1] == (spec, "paper", "0")
    assert len(rows) == 2 * EPISODES + 1
    doc = json.loads((out / "results.json").read_text())
    assert doc["complete"] is False
    assert spec in doc["error"] and str(EVAL_SEEDS[1]) in doc["error"]
    assert len(doc["episodes"]) == len(rows)
    assert not (out / "case_study.png").exists() and not (tmp_path / "report.md").exists()
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def test_illegal_action_with_workers_keeps_finished_episodes(tmp_path, capsys):
    # Each spawned worker counts its own calls: both finish one day, then fail.
    out = tmp_path / "out"
    rc = _run(out, agents=["tests.evaluation.test_evaluate:IllegalAfterK"], workers=2,
              episodes=4)
    assert rc == 1
    assert "IllegalAfterK" in capsys.readouterr().err
    rows = _rows(out / "episodes.csv")
    assert 1 <= len(rows) < 8
    doc = json.loads((out / "results.json").read_text())
    assert doc["complete"] is False and len(doc["episodes"]) == len(rows)


def test_report_has_tables_and_image_links(serial_run):
    _, out, report = serial_run
    text = report.read_text()
    assert "python -m agents.evaluate" in text and f"EVAL_SEEDS[:{EPISODES}]" in text
    assert "## paper (case 1, no uncertainty)" in text
    assert "## paper_uncertain (case 2, with uncertainty)" in text
    assert text.count("| metric | random | FirstLegal |") == 2
    assert "| total reward |" in text and "| unresolved conflicts |" in text
    assert "| collisions |" not in text and "| depletions" not in text  # one label a quantity
    for name in ("case_study.png", "action_distribution.png"):
        rel = os.path.relpath(out / name, report.parent)
        assert f"]({Path(rel).as_posix()})" in text
        assert (report.parent / rel).is_file()


def test_atomic_write_keeps_old_file_on_failure(tmp_path, monkeypatch):
    import agents.common.files as files

    path = tmp_path / "episodes.csv"
    files.write_atomic(path, "old\n")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(files.os, "replace", broken_replace)
    with pytest.raises(OSError):
        files.write_atomic(path, "new\n")
    assert path.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["episodes.csv"]


def test_parse_overrides():
    assert ev.parse_overrides(["schedule.episode_steps=60", "uncertainty.wind_gust_prob=0.1",
                               "layout.hover_spots_xy_m=[[1, 2]]"]) == (
        ("schedule.episode_steps", 60), ("uncertainty.wind_gust_prob", 0.1),
        ("layout.hover_spots_xy_m", [[1, 2]]))
    with pytest.raises(ev.InputError):
        ev.parse_overrides(["no_equals_sign"])


def test_seed_range_and_suite(tmp_path):
    """--seeds runs exactly those days; a suite file gives agents, cases and seeds; a seed
    count that disagrees with --episodes is refused."""
    argv = ["--agents", "random", "--configs", "paper", "--workers", "1", *TINY]
    assert ev.main([*argv, "--seeds", "800000:800002", "--out", str(tmp_path / "a")]) == 0
    assert [r["seed"] for r in _rows(tmp_path / "a" / "episodes.csv")] == ["800000", "800001"]
    assert ev.main([*argv, "--seeds", "800000:800002", "--episodes", "3",
                    "--out", str(tmp_path / "b")]) == 2
    suite = tmp_path / "suite.yaml"
    suite.write_text("name: mini\nagents: [fcfs]\nconfigs: [small]\nseeds: '1000500:1000501'\n")
    assert ev.main(["--suite", str(suite), "--workers", "1", *TINY,
                    "--out", str(tmp_path / "c")]) == 0
    rows = _rows(tmp_path / "c" / "episodes.csv")
    assert [(r["agent"], r["config"], r["seed"]) for r in rows] == [("fcfs", "small", "1000500")]
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nconfigs: [paper]\nepisodez: 3\n")
    assert ev.main(["--suite", str(bad), "--out", str(tmp_path / "d")]) == 2


def test_a_suite_with_fewer_episodes_keeps_its_own_first_days(tmp_path):
    """--episodes N with a suite plays the first N of the suite's seeds, never the days of
    another evaluation; more days than the suite has is refused."""
    argv = ["--suite", "transfer", "--agents", "fcfs", "--configs", "paper", "--workers", "1",
            *TINY]
    assert ev.main([*argv, "--episodes", "2", "--out", str(tmp_path / "a")]) == 0
    assert [r["seed"] for r in _rows(tmp_path / "a" / "episodes.csv")] == ["1000100", "1000101"]
    settings = json.loads((tmp_path / "a" / "results.json").read_text())["settings"]
    assert settings["seeds"] == [1000100, 1000101]
    assert ev.main([*argv, "--episodes", "31", "--out", str(tmp_path / "b")]) == 2
    assert not (tmp_path / "b").exists()


@pytest.mark.parametrize("given, expected", [
    (["EPISODES=2"], "--suite transfer --episodes 2 "),
    ([], "--suite transfer --out"),
])
def test_make_evaluate_passes_episodes_on_to_a_suite(given, expected):
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run(["make", "-n", "-o", ".venv/.installed", "evaluate", "SUITE=transfer",
                          *given], cwd=root, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    line = next(l for l in out.stdout.splitlines() if "evaluate --suite" in l)
    assert expected in " ".join(line.split()) + " "


@pytest.mark.parametrize("path", sorted(ev.SUITE_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_suites_name_real_configs_agents_and_test_seeds(path):
    from agents.controllers.registry import make_controller
    from agents.common.seeds import EVAL_SEED_BASE, parse_seed_range
    from marl_vertiport import load_config

    suite = ev.load_suite(path.stem)
    for config in suite.configs:
        load_config(config)  # raises on an unknown or broken config
    for agent in suite.agents:
        assert callable(make_controller(agent).act)
    seeds = parse_seed_range(suite.seeds)
    assert seeds.start >= EVAL_SEED_BASE  # reported numbers come from test seeds


def test_console_table_shows_the_bootstrap_interval_and_na_for_one_episode():
    settings = ev.EvalSettings(agents=("a",), configs=("paper",), episodes=3)
    row = {"agent": "a", "config": "paper", "metric": "total_reward", "mean": 100.0, "std": 9.0,
           "ci_low": 80.0, "ci_high": 130.0, "n": 3}
    text = ev.format_table(ev.Evaluation(settings, [], {}, ["total_reward"], [row]))
    assert "100 [80, 130]" in text and "±" not in text  # asymmetric, as in the report
    single = {**row, "ci_low": 100.0, "ci_high": 100.0, "n": 1}
    text = ev.format_table(ev.Evaluation(settings, [], {}, ["total_reward"], [single]))
    assert "100 [n/a]" in text and "one episode: no interval" in text


def test_agent_help_names_every_builtin_and_the_other_forms(capsys):
    from agents.controllers.registry import BUILTIN

    with pytest.raises(SystemExit):
        ev.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in [*BUILTIN, "gcn"]:
        assert name in text
    assert ".pt" in text and "package.module:Class" in text and "dispatcher[holding=false]" in text


def test_agent_spec_carries_constructor_arguments():
    from agents.controllers.registry import AgentSpecError, make_controller, split_spec

    assert split_spec("dispatcher") == ("dispatcher", {})
    assert split_spec("dispatcher[holding=false, priority_margin_pct=2.5]") == (
        "dispatcher", {"holding": False, "priority_margin_pct": 2.5})
    assert split_spec("examples.custom_agent:ChargeFirst[]") == ("examples.custom_agent:ChargeFirst", {})
    controller = make_controller("dispatcher[holding=false,priority_margin_pct=2.5]")
    assert controller.holding is False and controller.priority_margin_pct == 2.5
    assert make_controller("dispatcher").holding is True
    # A value may be a spec with arguments of its own: the guard builds its rollout policy from it.
    nested = "guard[rollout_policy=dispatcher[arrival_priority_pct=40,holding=true],samples=2]"
    assert split_spec(nested) == ("guard", {
        "rollout_policy": "dispatcher[arrival_priority_pct=40,holding=true]", "samples": 2})
    guard = make_controller(nested)
    assert guard.own_rollout_policy.arrival_priority_pct == 40 and guard.settings.samples == 2
    guard.close()
    for bad, words in [("dispatcher[holding]", "not key=value"),
                       ("dispatcher[holding=false", "arguments look like"),
                       ("dispatcher[no_such_arg=1]", "no_such_arg"),
                       ("dispatcher[x=[1,]", "arguments look like"),
                       ("guard[rollout_policy=dispatcher[holding=false]", "arguments look like"),
                       ("dispatcher[holding=false][x=1]", "arguments look like"),
                       ("guard[rollout_policy=dispatcher[no_such_arg=1]]", "no_such_arg")]:
        with pytest.raises(AgentSpecError, match=re.escape(words)):
            make_controller(bad)


def test_agent_arguments_reach_the_worker_processes(tmp_path):
    """The spec string is all a worker gets: two settings of one controller, side by side."""
    assert _run(tmp_path, agents=("dispatcher", "dispatcher[holding=false]"), workers=2) == 0
    agents = {r["agent"] for r in _rows(tmp_path / "episodes.csv")}
    assert agents == {"dispatcher", "dispatcher[holding=false]"}


def test_a_crashing_controller_is_reported_with_its_file_and_line(tmp_path, capsys):
    spec = "tests.evaluation.test_evaluate:CrashesOnTurnThree"
    assert _run(tmp_path / "out", agents=[spec]) == 1
    err = capsys.readouterr().err
    line = next(i for i, text in enumerate(Path(__file__).read_text().splitlines(), 1)
                if "return self.turns // 0" in text)
    assert "ZeroDivisionError: integer division or modulo by zero" in err
    assert f"raised at tests/evaluation/test_evaluate.py:{line} in act" in err


@pytest.mark.parametrize("out, report, words", [
    ("a_file", None, "exists and is not a folder"),
    ("a_file/sub", None, "is not a folder"),
    ("out", ".", "is a folder; give a file name"),
])
def test_bad_outputs_are_refused_before_any_episode_runs(tmp_path, capsys, out, report, words):
    (tmp_path / "a_file").write_text("keep me")
    argv = ["--agents", "random", "--episodes", "1", "--out", str(tmp_path / out), *TINY]
    if report is not None:
        argv += ["--report", str(tmp_path / report)]
    assert ev.main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and "episodes in" not in err  # refused up front, nothing ran
    assert (tmp_path / "a_file").read_text() == "keep me"
