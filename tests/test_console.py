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
