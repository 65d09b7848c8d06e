"""The charger study (agents/studies/charger_study.py): its minutes add up, its energy is what the batteries
gained on the charger, and bad input is refused."""

import pytest

from agents.studies.charger_study import charger_day, main, summarise, table
from marl_vertiport.config import load_config


@pytest.mark.parametrize("config,chargers", [("paper", 1), ("twin", 2)])
def test_every_charger_minute_is_accounted_for_once(config, chargers):
    steps = 150
    day = charger_day("dispatcher", config, 3, 800_003, {"schedule.episode_steps": steps})
    total = day.approach_min + day.charging_min + day.parked_full_min + day.free_min
    # twin decides twice a minute: 150 steps are 75 minutes
    assert total == pytest.approx(steps * chargers * load_config(config).schedule.minutes_per_step)
    assert day.sessions >= 1 and day.charging_min > 0
    # At most 10 % a charging minute (the config's rate), and some charge delivered.
    assert 0 < day.delivered_pct <= 10.0 * day.charging_min + 1e-9
    row = summarise([day, day])
    assert row["fleet_size"] == 3 and row["charging_min"] == day.charging_min
    assert table([row]).splitlines()[2].startswith("| 3 |")


def test_training_seeds_and_bad_fleets_are_refused(capsys):
    assert main(["--seeds", "0:3"]) == 2
    assert "training seeds" in capsys.readouterr().err
    assert main(["--fleet", "0", "--seeds", "800000:800001"]) == 2
    assert "fleet" in capsys.readouterr().err


def test_soak_runs_checks_and_reports_what_it_covered(capsys):
    from agents.studies.soak import main

    assert main(["--days", "2", "--configs", "small", "paper"]) == 0
    out = capsys.readouterr().out
    assert "soak: 4 days (2 per layout: small (3 eVTOLs), paper (4 eVTOLs))" in out
    assert "invariants: all held" in out and "gusts" in out and "RSS" in out
    assert main(["--days", "1"]) == 2


def test_capacity_without_names_still_runs_the_charger_study_with_a_note(capsys):
    """Before 0.2.0 one ``capacity`` command did both jobs; with no names it was the study."""
    import agents.common.names as names
    from agents.studies.capacity import main as capacity_main

    names._noted.clear()
    with pytest.warns(names.RenamedWarning, match="charger-study"):
        assert capacity_main(["--fleet", "0"]) == 2  # the charger study's own check
    assert "fleet sizes must be >= 1" in capsys.readouterr().err
