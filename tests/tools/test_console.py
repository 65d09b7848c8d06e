"""The ``marl-vertiport`` console command: dispatch to each tool, help, errors, installed script."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from agents import cli


def test_every_command_names_a_module_with_main():
    for command, (module, _) in cli.COMMANDS.items():
        assert callable(getattr(importlib.import_module(module), "main", None)), command


def test_env_command_is_dispatched_with_its_arguments(capsys):
    assert cli.main(["info", "--config", "small"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("config: small; 3 eVTOLs") and "actions:" in out


def test_tool_command_passes_options_through_and_keeps_its_exit_code(capsys):
    assert cli.main(["evaluate", "--agents", "no_such_agent_xyz", "--episodes", "1"]) == 2
    assert "unknown agent 'no_such_agent_xyz'" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [[], ["no_such_command"]])
def test_missing_or_unknown_command_lists_the_commands(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "usage: marl-vertiport" in err
    if argv:
        assert "invalid choice: 'no_such_command'" in err and "'evaluate'" in err


def test_installed_script_runs_without_the_pybullet_banner():
    script = Path(sys.executable).with_name("marl-vertiport")
    assert script.exists(), "pip install -e . installs the marl-vertiport script"
    # ``info`` builds an env, so pybullet is imported.
    result = subprocess.run([str(script), "info", "--config", "small"], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("config: small")
    assert "pybullet build time" not in result.stdout + result.stderr


CONTROLLER = '''
class Patient:
    """Stays when it may, else takes the first legal action."""

    def act(self, observation):
        legal = [i for i, ok in enumerate(observation["action_mask"]) if ok]
        return 0 if 0 in legal else legal[0]
'''


def console(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).with_name("marl-vertiport")
    return subprocess.run([str(script), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_installed_command_loads_controllers_from_the_working_directory(tmp_path):
    """``module:Class`` and ``path/to/file.py:Class`` resolve from the folder the command runs
    in, as under ``python -m``, in this process and in the worker processes (two here)."""
    (tmp_path / "mine.py").write_text(CONTROLLER)
    (tmp_path / "ctrl").mkdir()
    (tmp_path / "ctrl" / "patient.py").write_text(CONTROLLER)
    quick = ["--configs", "paper", "--episodes", "2", "--set", "schedule.episode_steps=8",
             "--workers", "2", "--no-progress"]
    result = console("evaluate", "--agents", "mine:Patient", "ctrl/patient.py:Patient", *quick,
                     "--out", "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "out" / "episodes.csv").read_text()
    assert text.count("mine:Patient,paper") == 2 and text.count("ctrl/patient.py:Patient,paper") == 2
    result = console("sweep", "wind", "--agents", "ctrl/patient.py:Patient", "--episodes", "1",
                     "--grid", "uncertainty.wind_gust_prob=0,0.1", "--set",
                     "schedule.episode_steps=8", "--workers", "2", "--no-progress",
                     "--out", "sweep", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "sweep" / "sweep.csv").read_text().count("ctrl/patient.py:Patient") == 2


@pytest.mark.parametrize("spec, message", [
    ("mine:Patiant", "module 'mine' has no attribute 'Patiant'; did you mean 'Patient'?"),
    ("mine.py:Patiant", "file 'mine.py' has no attribute 'Patiant'; did you mean 'Patient'?"),
    ("nowhere.py:Patient", "cannot import file 'nowhere.py': no such file"),
    ("minez:Patient", "cannot import module 'minez': no module named 'minez' in the working "
                      "directory"),
])
def test_a_typo_in_a_controller_spec_names_what_is_missing(tmp_path, spec, message):
    (tmp_path / "mine.py").write_text(CONTROLLER)
    result = console("evaluate", "--agents", spec, "--episodes", "1", cwd=tmp_path)
    assert result.returncode == 2
    assert message in result.stderr


def test_the_example_controller_loads_from_the_checkout_through_the_console_command(tmp_path):
    root = Path(__file__).resolve().parents[2]
    result = console("evaluate", "--agents", "examples.custom_agent:ChargeFirst", "--configs",
                     "paper", "--episodes", "1", "--set", "schedule.episode_steps=8",
                     "--workers", "1", "--no-progress", "--out", str(tmp_path / "out"), cwd=root)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("command", ["evaluate", "sweep", "train", "curves", "render", "bench",
                                     "capacity", "soak", "demo", "info", "check-config"])
def test_help_names_the_command_as_typed(command, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: marl-vertiport {command}")
    assert "python -m" not in out.splitlines()[0]
