"""The paper's case-study claims beside the project's measurements: the shipped page is what
the command makes from the shipped results, and a claim is marked by where its paired interval
lies."""

import csv

import pytest

from agents.studies import paper_claims
from agents.studies.paper_claims import CLAIMS, ClaimsError, measure, read_days, table

ROOT = paper_claims.REPO_ROOT


def test_the_shipped_page_is_what_the_command_makes_from_the_shipped_results():
    days = read_days(paper_claims.DEFAULT_EPISODES)
    shipped = (ROOT / "docs" / "results" / "paper_claims.md").read_text()
    assert shipped == table(days, "docs/results/episodes.csv")
    assert "14 of 15 claims reproduced" in shipped  # what the guide quotes


def _write(path, rows):
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["agent", "config", "episode", "seed", *paper_claims.LABELS])
        writer.writerows(rows)
    return path


def test_a_claim_is_marked_by_where_its_interval_lies(tmp_path):
    rows = []
    for seed in range(20):
        for agent, reward in (("gcn", 100.0), ("heuristic", 300.0), ("fcfs", 200.0),
                              ("random", -50.0 + seed)):
            for case in ("paper", "paper_uncertain"):
                rows.append([agent, case, seed, seed, reward + seed % 3, 1, 50, 10, 5, 5])
    days = read_days(_write(tmp_path / "episodes.csv", rows))
    ahead_of_fcfs = CLAIMS[0]
    assert measure(ahead_of_fcfs, days)["verdict"] == "reversed"  # GRL 100 < FCFS 200
    assert measure(ahead_of_fcfs, days, "dispatcher")["verdict"] == "reproduced"  # old label read
    reward_drop = next(c for c in CLAIMS if c.text == "GRL's reward drops")
    assert measure(reward_drop, days)["verdict"] == "not separated"  # the same in both cases


def test_missing_agents_are_named(tmp_path):
    days = read_days(_write(tmp_path / "e.csv", [["gcn", "paper", 0, 0, 1, 1, 1, 1, 1, 1]]))
    with pytest.raises(ClaimsError, match="fcfs on paper"):
        measure(CLAIMS[0], days)
    assert paper_claims.main(["--episodes", str(tmp_path / "e.csv")]) == 2
