"""The per-decision log (agents/controllers/decisions.py): it changes nothing in the day, every
masked action has its reason, the learned ATC's probabilities, who decided, the vehicles lost
named, and the CSV and JSON files."""

import csv
import json

import numpy as np
import pytest

from agents.controllers.decisions import COLUMNS, DecisionLog, action_probabilities, format_events
from agents.controllers.episode import run_episode
from agents.controllers.registry import make_controller
from marl_vertiport import vertiport_v1

REASONS = ("status", "occupancy", "energy", "separation")


def _day(spec, config, seed, steps=None, log=True):
    policy = make_controller(spec)
    env = vertiport_v1.env(config=config)
    dlog = DecisionLog(policy) if log else None
    metrics = run_episode(env, policy, seed, max_steps=steps,
                          before_step=dlog.before_step if log else None,
                          after_step=dlog.after_step if log else None)
    return metrics, dlog, env


@pytest.mark.slow
@pytest.mark.parametrize("spec, config", [("gcn", "paper_uncertain"), ("dispatcher", "paper")])
def test_the_log_changes_nothing_and_explains_every_masked_action(spec, config):
    with_log, log, env = _day(spec, config, 1000004)
    without, _, _ = _day(spec, config, 1000004, log=False)
    assert with_log == without  # reading the masks' reasons and the policy changes nothing
    sim = env.unwrapped.sim
    names = sim.actions.names(sim.layout)
    assert [r["step"] for r in log.rows] == list(range(1440))
    for row in log.rows:
        assert set(row) == set(COLUMNS)
        legal = set(row["probabilities"]) if row["probabilities"] else None
        masked = set(row["masked"])
        assert len(masked) == len(names) - row["legal"]
        assert row["recommendation_name"] not in masked
        assert all(r.startswith(REASONS) for r in row["masked"].values()), row["masked"]
        if legal is not None:  # the learned ATC: a probability for every legal action
            assert legal.isdisjoint(masked) and len(legal) == row["legal"]
            assert abs(sum(row["probabilities"].values()) - 1) < 1e-3
            assert row["policy_choice"] == row["recommendation_name"]  # greedy
        else:
            assert row["policy_choice"] == "" and row["policy_probability"] is None
    assert sum(r["reward"] for r in log.rows) == pytest.approx(with_log["total_reward"], abs=1e-2)
    # A separation reason names the vehicles in the way (or, for an avoidance climb, that no
    # layer clears).
    sep = [r for row in log.rows for r in row["masked"].values() if r.startswith("separation")]
    assert any(r.startswith("separation: evtol_") for r in sep)
    assert all(r.startswith(("separation: evtol_", "separation (no avoidance layer")) for r in sep)


def test_the_handed_back_atc_logs_who_decided_and_the_policys_own_choice():
    _, log, _ = _day("lookahead", "paper", 1000002, steps=200)
    by = {r["decided_by"] for r in log.rows}
    assert "lookahead: gcn:gcn_default.pt" in by and "lookahead: dispatcher" in by
    handed = [r for r in log.rows if r["decided_by"] == "lookahead: dispatcher" and r["legal"] > 1]
    assert handed and all(r["probabilities"] for r in handed)  # the proposal it overruled
    assert any(r["policy_choice"] != r["recommendation_name"] for r in handed)


def test_the_vehicles_lost_are_named_on_the_step_they_are_lost():
    metrics, log, env = _day("random", "paper", 1000000)
    named = [v for r in log.rows if "vehicle lost: " in r["events"]
             for v in r["events"].split("vehicle lost: ")[1].split(";")[0].split(", ")]
    assert metrics["stranded"] > 0 and len(named) == metrics["stranded"]
    lost = np.flatnonzero(env.unwrapped.sim.lost)
    assert sorted(named) == sorted(f"evtol_{v}" for v in lost)


def test_files_are_written_whole_with_the_same_rows(tmp_path):
    _, log, _ = _day("gcn", "paper", 1000001, steps=50)
    csv_path, json_path, choices_path = log.write(tmp_path / "day", {"agent": "gcn"})
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    doc = json.loads(json_path.read_text())
    assert doc["meta"] == {"agent": "gcn"} and doc["columns"] == list(COLUMNS)
    assert len(rows) == len(doc["rows"]) == 50
    for flat, nested in zip(rows, doc["rows"]):
        assert int(flat["recommendation"]) == nested["recommendation"]
        assert flat["probabilities"].split(";")[0].split()[0] == next(iter(nested["probabilities"]))
        assert len(flat["masked"].split("; ")) == len(nested["masked"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["day.choices.csv", "day.csv", "day.json"]
    with open(choices_path, newline="") as f:
        choices = list(csv.DictReader(f))
    # The real decisions alone: every turn with more than one legal action, none without.
    assert [r["step"] for r in choices] == [r["step"] for r in rows if int(r["legal"]) > 1]
    assert 0 < len(choices) < len(rows)


def test_rules_have_no_probabilities_and_events_read_as_words():
    obs = {"action_mask": np.array([1, 1, 0], dtype=np.int8)}
    assert action_probabilities(make_controller("dispatcher"), obs) is None
    assert format_events({}) == ""
    words = format_events({"takeoff": True, "good_takeoff": True, "contacts": 1,
                           "vehicles_lost": 2, "action": 3, "commanded_action": 4}, lost=[1, 3])
    assert words == "take-off; contact; vehicle lost: evtol_1, evtol_3; instruction misread"
