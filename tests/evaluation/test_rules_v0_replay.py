"""The env's rules v0 keep their numbers: the first day of every agent x case of the results
shipped before the separation check (docs/results at commit a790a05, made under rules v0; kept
in tests/data/v0_results) replays exactly, every column, under ``vertiport_v0``.

The dispatcher's rows are the exception: it has since learnt to adopt the env's energy model
(``DispatcherController.bind``), so it decides otherwise under v0 too. The rows of random, FCFS
and the shipped policy, nine days, are what show the env unchanged."""

from __future__ import annotations

from pathlib import Path

from agents.checks import results as check

V0_SET = Path(__file__).resolve().parents[1] / "data" / "v0_results" / "results.json"


def test_the_rules_v0_replay_the_results_made_under_them_exactly():
    from agents.execution import LocalBackend

    result = check.read_set(V0_SET)
    assert "env" not in result.provenance  # made before results recorded their rules: v0
    header, rows = check.read_rows(result)
    assert len(rows) == 12  # random, fcfs, heuristic and the shipped policy on three cases
    assert all(task.rules == 0 for task in check.tasks_of(result, rows))
    problems = check.replay([result], 1, LocalBackend(1), progress=False)[result.name]
    assert [p for p in problems if not p.startswith("heuristic /")] == []
