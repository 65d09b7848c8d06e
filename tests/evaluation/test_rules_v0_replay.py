"""The env's rules v0 keep their numbers: the first day of every agent x case of the results
shipped before the separation check (docs/results at commit a790a05, made under rules v0; kept
in tests/data/v0_results) replays exactly, every column, under ``vertiport_v0``.

The policy those results played was the shipped checkpoint of the time; it is kept beside
them (``gcn_default_v0.pt``, the SHA-256 the record names) and replayed in place of ``gcn``,
which has since been retrained under rules v1.

The dispatcher's rows are the exception: it has since learnt to adopt the env's energy model
(``DispatcherController.bind``), so it decides otherwise under v0 too. The rows of random, FCFS
and that policy, nine days, are what show the env unchanged."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

from agents.checks import results as check
from agents.common.provenance import file_sha256

V0_DIR = Path(__file__).resolve().parents[1] / "data" / "v0_results"
V0_SET = V0_DIR / "results.json"
V0_CHECKPOINT = V0_DIR / "gcn_default_v0.pt"


def _with_the_v0_policy(tmp_path: Path) -> Path:
    """A copy of the set whose ``gcn`` rows name the kept v0 checkpoint by path."""
    shutil.copy(V0_SET, tmp_path / "results.json")
    with (V0_DIR / "episodes.csv").open(newline="") as fh:
        reader = csv.DictReader(fh)
        header, rows = list(reader.fieldnames or []), list(reader)
    for row in rows:
        if row["agent"] == "gcn":
            row["agent"] = str(V0_CHECKPOINT)
    with (tmp_path / "episodes.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, header, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return tmp_path / "results.json"


def test_the_kept_checkpoint_is_the_one_the_v0_results_played():
    record = check.read_set(V0_SET).provenance
    assert record["checkpoints"]["gcn"]["sha256"] == file_sha256(V0_CHECKPOINT)


def test_the_rules_v0_replay_the_results_made_under_them_exactly(tmp_path):
    from agents.execution import LocalBackend

    result = check.read_set(_with_the_v0_policy(tmp_path))
    assert "env" not in result.provenance  # made before results recorded their rules: v0
    header, rows = check.read_rows(result)
    assert len(rows) == 12  # random, fcfs, heuristic and the shipped policy on three cases
    assert sum(row["agent"] == str(V0_CHECKPOINT) for row in rows) == 3
    assert all(task.rules == 0 for task in check.tasks_of(result, rows))
    problems = check.replay([result], 1, LocalBackend(1), progress=False)[result.name]
    assert [p for p in problems if not p.startswith("heuristic /")] == []
