"""The shipped results are never stale (agents/checks/results.py).

Every result set under docs/ names the shipped checkpoint (by SHA-256) and committed code, its
figures and reports carry the same record, and (``-m replay``, ``make check-results``, run by
``.ci/run``) the first 2 days of every agent x case (x sweep point) of its CSV replay exactly on
the code as it is."""

from __future__ import annotations

import csv
import re
import subprocess

import pytest

from agents.checks import results as check
from agents.common.provenance import REPO_ROOT, file_sha256, read_png_metadata
from agents.common.specs import checkpoint_files
from agents.controllers.registry import SHIPPED_CHECKPOINT

DOCS = REPO_ROOT / "docs"
SETS = check.find_sets(DOCS)
#: The sets the docs report on; a missing one is a missing result, not a pass.
EXPECTED = {"docs/results", "docs/results/bar", "docs/results/transfer", "docs/results/scaling",
            "docs/results/sweeps/wind", "docs/results/safety/u00", "docs/results/safety/u05",
            "docs/results/safety/u10"}
#: Figures of docs/ that may lack a provenance record: none. (The learning curves of PPO from
#: scratch, made before figures recorded it, live with their experiments in experiments/.)
UNRECORDED_FIGURES: set[str] = set()


def test_the_expected_result_sets_are_shipped():
    assert {s.name for s in SETS} == EXPECTED


@pytest.mark.parametrize("result", SETS, ids=lambda s: s.name)
def test_every_shipped_result_names_the_shipped_checkpoint_and_committed_code(result):
    assert check.record_problems(result, SHIPPED_CHECKPOINT) == []
    # Every set plays the shipped policy: alone (gcn) or inside a look-ahead (lookahead).
    assert any(SHIPPED_CHECKPOINT in checkpoint_files(agent) for agent in result.agents)


@pytest.mark.parametrize("result", SETS, ids=lambda s: s.name)
def test_the_code_a_result_names_is_in_this_history(result):
    commit = result.provenance["code"]["commit"]
    assert re.fullmatch(r"[0-9a-f]{40}", commit)
    known = subprocess.run(["git", "-C", str(REPO_ROOT), "cat-file", "-e", f"{commit}^{{commit}}"],
                           capture_output=True)
    if known.returncode != 0:
        pytest.skip(f"commit {commit[:12]} is not in this clone (a shallow clone?)")
    ancestor = subprocess.run(["git", "-C", str(REPO_ROOT), "merge-base", "--is-ancestor",
                               commit, "HEAD"], capture_output=True)
    assert ancestor.returncode == 0, f"{commit[:12]} is not an ancestor of HEAD"


@pytest.mark.parametrize("result", SETS, ids=lambda s: s.name)
def test_figures_and_reports_carry_the_same_record(result):
    folder = result.record_path.parent
    pngs = sorted(folder.glob("*.png"))
    assert pngs
    for png in pngs:
        assert read_png_metadata(png) == result.provenance, png.name
    sha = file_sha256(SHIPPED_CHECKPOINT)[:16]
    reports = [folder.with_suffix(".md")] if folder.with_suffix(".md").exists() else []
    for report in reports:
        assert f"gcn_default.pt sha256 {sha}" in report.read_text(), report


def test_the_benchmark_and_the_shipped_learning_curves_name_committed_code():
    text = (DOCS / "performance.md").read_text()
    match = re.search(r"Made with code ([0-9a-f]{12}) \(clean\)", text)
    assert match, "docs/performance.md names the code it measured"
    record = read_png_metadata(DOCS / "performance_fleet.png")
    assert record and record["code"]["commit"].startswith(match.group(1))
    curves = read_png_metadata(DOCS / "learning_curves.png")
    assert curves and curves["code"]["dirty"] is False
    unrecorded = {p.name for p in DOCS.glob("*.png") if read_png_metadata(p) is None}
    assert unrecorded <= UNRECORDED_FIGURES


def test_a_result_record_with_another_checkpoint_or_dirty_code_is_refused(tmp_path):
    result = check.ResultSet(tmp_path / "results.json", tmp_path / "episodes.csv",
                             ["gcn", "fcfs"], {})
    assert check.record_problems(result, SHIPPED_CHECKPOINT) == [
        "no provenance record: made before results recorded it; regenerate the set"]
    result.provenance = {"code": {"commit": "a" * 40, "dirty": True},
                         "checkpoints": {"gcn": {"path": "agents/checkpoints/gcn_default.pt",
                                                 "sha256": "0" * 64}}}
    problems = check.record_problems(result, SHIPPED_CHECKPOINT)
    assert len(problems) == 2
    assert "uncommitted changes" in problems[0] and "not the shipped checkpoint" in problems[1]


def test_a_replay_finds_a_cell_that_the_code_no_longer_gives(tmp_path):
    """A small evaluation written now replays clean; one number changed by hand is caught,
    named by agent, case, seed and column."""
    from agents.evaluate.cli import main
    from agents.execution import LocalBackend

    out = tmp_path / "set"
    assert main(["--agents", "fcfs", "dispatcher", "--configs", "paper", "--episodes", "3",
                 "--set", "schedule.episode_steps=40", "--workers", "1", "--no-progress",
                 "--out", str(out)]) == 0
    result = check.read_set(out / "results.json")
    assert result.overrides == {"schedule.episode_steps": 40}
    assert check.replay([result], 2, LocalBackend(1), progress=False) == {result.name: []}
    rows = list(csv.DictReader((out / "episodes.csv").open()))
    rows[1]["total_reward"] = f"{float(rows[1]['total_reward']) + 0.001:.10g}"
    with (out / "episodes.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    problems = check.replay([result], 2, LocalBackend(1), progress=False)[result.name]
    assert len(problems) == 1
    assert problems[0].startswith(f"fcfs / paper / seed {rows[1]['seed']}: total_reward: shipped")


@pytest.mark.replay
@pytest.mark.parametrize("result", SETS, ids=lambda s: s.name)
def test_the_first_two_days_of_every_shipped_row_replay_exactly(result):
    from agents.execution import LocalBackend

    problems = check.replay([result], 2, LocalBackend(2), progress=False)[result.name]
    assert problems == [], "\n".join(problems[:20])
