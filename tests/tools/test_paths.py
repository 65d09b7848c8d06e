"""Paths a user controls and errors a user can read: ``make render`` writes where ``OUT`` says,
an evaluation records the file of a controller named by path so that ``worst-day`` rebuilds it
from any folder (and refuses a file changed since), and every ``marl-vertiport`` error is one
line unless ``--debug`` asks for the traceback."""

import shutil
import subprocess
from pathlib import Path

import pytest

from agents import cli
from agents.evaluate.cli import main as evaluate
from agents.render import worst_day

ROOT = Path(__file__).resolve().parents[2]

CONTROLLER = '''
import numpy as np


class FirstLegal:
    """The lowest-numbered legal action."""

    def act(self, observation):
        return int(np.flatnonzero(observation["action_mask"])[0])
'''


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_render_writes_where_out_says(tmp_path):
    text = subprocess.run(["make", "-n", "-s", "render", f"OUT={tmp_path}", "AGENT=fcfs"],
                          cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert f"--out {tmp_path}/fcfs_paper.gif" in text
    default = subprocess.run(["make", "-n", "-s", "render"], cwd=ROOT, capture_output=True,
                             text=True, check=True).stdout
    assert "--out runs/render/dispatcher_paper.gif" in default


def test_worst_day_rebuilds_a_file_controller_from_another_folder(tmp_path, monkeypatch, capsys):
    home, elsewhere = tmp_path / "home", tmp_path / "elsewhere"
    home.mkdir()
    elsewhere.mkdir()
    (home / "mine.py").write_text(CONTROLLER)
    run = tmp_path / "run"
    monkeypatch.chdir(home)
    assert evaluate(["--agents", "mine.py:FirstLegal", "--configs", "paper", "--episodes", "1",
                     "--set", "schedule.episode_steps=30", "--workers", "1", "--no-progress",
                     "--out", str(run)]) == 0
    import json

    record = json.loads((run / "results.json").read_text())["provenance"]["controllers"]
    assert record["mine.py:FirstLegal"]["file"] == str((home / "mine.py").resolve())
    monkeypatch.chdir(elsewhere)  # mine.py is not here: the record says where it was
    assert worst_day.main([str(run), "--size", "160x120", "--window-min", "5",
                           "--no-progress"]) == 0
    assert "| yes |" in (run / "worst_day" / "index.md").read_text()
    (home / "mine.py").write_text(CONTROLLER + "\n# changed\n")
    capsys.readouterr()
    assert worst_day.main([str(run), "--no-progress"]) == 2
    error = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error")]
    assert len(error) == 1 and "changed since the run" in error[0]


def test_every_command_error_is_one_line_unless_debug(monkeypatch, capsys):
    import agents.studies.soak as soak

    def broken(argv, prog):
        raise RuntimeError("something broke\nat a place the user does not need")

    monkeypatch.setattr(soak, "main", broken)
    assert cli.main(["soak"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: something broke at a place")
    assert "--debug" in err
    with pytest.raises(RuntimeError, match="something broke"):
        cli.main(["soak", "--debug"])
