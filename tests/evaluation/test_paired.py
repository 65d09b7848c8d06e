"""Paired comparison of agents on the same days (agents/evaluate/paired.py)."""

import csv

import pytest

from agents.evaluate.paired import PairedInputError, compare, main, read_episodes

COLUMNS = ["agent", "config", "episode", "seed", "total_reward", "stranded_air",
           "stranded_ground", "collisions"]


def write(path, rows):
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        writer.writerows(rows)
    return path


def episodes(tmp_path):
    rows = []
    for case in ("paper", "wide"):
        for k, seed in enumerate(range(800000, 800004)):
            base = 1000.0 + 100 * k + (0 if case == "paper" else -500)
            rows.append(["a", case, k, seed, base, 0, 1, 0])
            # b: +30 on paper, -10 on wide; one more vehicle lost on the ground on wide
            rows.append(["b", case, k, seed, base + (30 if case == "paper" else -10), 0,
                         1 if case == "paper" else 2, 0])
    rows.append(["c", "paper", 0, 900000, 1.0, 0, 0, 0])  # a day nobody else played
    return write(tmp_path / "episodes.csv", rows)


def test_paired_difference_is_per_day_and_pools_pairs(tmp_path):
    data = read_episodes([episodes(tmp_path)])
    row, = compare(data, [("a", "b")])
    assert row["days"] == 8 and row["difference"] == pytest.approx(10.0)
    assert row["by_case"] == {"paper": pytest.approx(30.0), "wide": pytest.approx(-10.0)}
    assert row["by_case_ci"]["paper"] == pytest.approx((30.0, 30.0))  # the same gain every day
    assert row["ci_low"] <= 10.0 <= row["ci_high"] and row["ci_low"] < row["ci_high"]
    assert row["stranded_ground_base"] == 1.0 and row["stranded_ground_candidate"] == 1.5
    rows = compare(data, [("a", "b"), ("b", "a")])
    assert [r["pair"] for r in rows][-1] == "all" and rows[-1]["days"] == 16
    assert rows[-1]["difference"] == pytest.approx(0.0)


def test_cli_prints_the_table_and_writes_the_csv(tmp_path, capsys):
    out = tmp_path / "paired.csv"
    assert main([str(episodes(tmp_path)), "--pair", "a", "b", "--csv", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| a → b | 8 |" in table and "+10 [" in table and "0.00 / 1.00 → 0.00 / 1.50" in table
    rows = list(csv.DictReader(out.open()))
    assert rows[0]["difference_paper"] == "30.0" and rows[0]["days"] == "8"
    assert rows[0]["ci_low_wide"] == rows[0]["ci_high_wide"] == "-10.0"
    assert "+30 [+30, +30] | -10 [-10, -10] |" in table  # each case with its interval


@pytest.mark.parametrize("pair, message", [
    (("a", "zz"), "agent 'zz' is in none of the files .*a, b, c"),
    (("a", "c"), "played no day in common"),
])
def test_bad_pairs_are_named(tmp_path, pair, message):
    with pytest.raises(PairedInputError, match=message):
        compare(read_episodes([episodes(tmp_path)]), [pair])


def test_bad_files_are_named(tmp_path, capsys):
    foreign = tmp_path / "summary.csv"
    foreign.write_text("agent,config,metric\nx,paper,total_reward\n")
    with pytest.raises(PairedInputError, match="summary.csv: not an episodes.csv .*seed"):
        read_episodes([foreign])
    bad = write(tmp_path / "bad.csv", [["a", "paper", 0, "x", 1, 0, 0, 0]])
    with pytest.raises(PairedInputError, match="bad.csv, line 2"):
        read_episodes([bad])
    other = write(tmp_path / "other.csv", [["a", "paper", 0, 800000, 5.0, 0, 0, 0]])
    with pytest.raises(PairedInputError, match="differs from another file"):
        read_episodes([episodes(tmp_path), other])
    assert main([str(tmp_path / "missing.csv"), "--pair", "a", "b"]) == 2
    assert "missing.csv: cannot be read" in capsys.readouterr().err


def test_unforced_losses_count_what_no_reference_agent_also_lost(tmp_path):
    rows = []
    for k, seed in enumerate(range(800000, 800004)):
        rows.append(["dispatcher", "paper", k, seed, 1000.0, 0, 1, 0])  # loses 1 every day
        rows.append(["planner", "paper", k, seed, 1100.0, 0, k % 2, 0])  # 0 on even days
        rows.append(["x", "paper", k, seed, 900.0, 1, 1, 0])  # loses 2 every day
    data = read_episodes([write(tmp_path / "ref.csv", rows)])
    row, = compare(data, [("dispatcher", "x")], reference=("dispatcher", "planner"))
    # The fewest lost by a reference agent: 0, 1, 0, 1; x loses 2: 2, 1, 2, 1.
    assert row["reference_days"] == 4
    assert row["unforced_base"] == pytest.approx(0.5) and row["unforced_candidate"] == 1.5
    row, = compare(data, [("dispatcher", "x")])  # no reference set
    assert row["reference_days"] == 0 and row["unforced_candidate"] is None
    with pytest.raises(PairedInputError, match="reference agent 'guard' is in none"):
        compare(data, [("dispatcher", "x")], reference=("guard",))


def test_cli_takes_the_reference_agents_the_files_hold(tmp_path, capsys):
    path = episodes(tmp_path)  # agents a, b, c: neither reference agent by default
    assert main([str(path), "--pair", "a", "b"]) == 0
    assert "(reference: none given)" in capsys.readouterr().out
    assert main([str(path), "--pair", "a", "b", "--reference", "a"]) == 0
    table = capsys.readouterr().out
    # b loses one more on the ground on wide (4 of the 8 days): 0.50 a day beyond a.
    assert "(reference: a)" in table and "0.00 → 0.50 (8 days)" in table
    assert main([str(path), "--pair", "a", "b", "--reference", "zz"]) == 2
    assert "reference agent 'zz'" in capsys.readouterr().err


def test_the_command_runs_without_a_warning():
    """``python -m agents.evaluate.paired`` imports the package first; were ``paired`` among
    the package's imports, runpy would warn that the module was imported before it ran."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-m",
                          "agents.evaluate.paired", "--help"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "RuntimeWarning" not in out.stderr
    assert "--pair BASE CANDIDATE" in out.stdout
