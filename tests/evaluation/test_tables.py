"""Names a reader cannot misread: the console table fits 120 columns and shows the vehicles
lost and the contacts; the files gain ``vehicles_lost`` beside the columns they keep; the
paper's "collisions" are called unresolved conflicts wherever a person reads them; and the
report ranks no metric that a run leaves undefined."""

import csv

from agents.evaluate.cli import main as evaluate
from agents.evaluate.metrics import METRIC_LABELS, TABLE_METRICS, VEHICLES_LOST, axis_label
from agents.evaluate.tables import TABLE_WIDTH


def _run(tmp_path, capsys, *extra):
    out = tmp_path / "run"
    assert evaluate(["--agents", "random", "dispatcher", "examples.custom_agent:ChargeFirst",
                     "--configs", "paper", "--episodes", "2", "--workers", "1", "--no-progress",
                     "--set", "schedule.episode_steps=80", "--out", str(out),
                     "--report", str(out / "report.md"), *extra]) == 0
    return out, capsys.readouterr().out


def test_the_console_table_fits_120_columns_and_shows_losses_and_contacts(tmp_path, capsys):
    out, printed = _run(tmp_path, capsys)
    table = printed.split("\n\n")[0].splitlines()
    assert max(len(line) for line in table) <= TABLE_WIDTH
    assert "lost" in table[1] and "contacts" in table[1] and "unres. conflicts" in table[1]
    assert {"total_reward", VEHICLES_LOST, "contacts"} <= set(TABLE_METRICS)
    assert "not contacts" in printed  # the note says what the conflicts are


def test_the_files_gain_vehicles_lost_and_keep_their_columns(tmp_path, capsys):
    out, _ = _run(tmp_path, capsys)
    with (out / "episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    header = list(rows[0])
    assert header.index(VEHICLES_LOST) == header.index("stranded") + 1
    for kept in ("collisions", "stranded_air", "stranded_ground", "stranded", "battery_depletions"):
        assert kept in header
    for row in rows:
        assert row[VEHICLES_LOST] == row["stranded"]
        assert int(row["stranded"]) == int(row["stranded_air"]) + int(row["stranded_ground"])


def test_collisions_are_called_unresolved_conflicts_where_people_read_them():
    assert METRIC_LABELS["collisions"] == "unresolved conflicts"
    assert "unresolved predicted conflicts" in axis_label("collisions")
    assert METRIC_LABELS[VEHICLES_LOST] == "vehicles lost"
    labels = [METRIC_LABELS[m] for m in ("stranded_air", "stranded_ground", VEHICLES_LOST)]
    assert labels == ["lost in the air", "lost on the ground", "vehicles lost"]


def test_the_report_ranks_no_metric_a_run_leaves_undefined(tmp_path, capsys):
    """With a fleet of one the minimum separation is NaN on every day: the report does not say
    which agent's NaN is highest, nor that NaN intervals do not overlap."""
    out, _ = _run(tmp_path, capsys, "--set", "fleet_size=1")
    report = (out / "report.md").read_text()
    findings = [line for line in report.splitlines() if line.startswith("- ")]
    assert findings and not any(line.startswith("- min separation") for line in findings)
    assert "nan" not in " ".join(findings).lower()
