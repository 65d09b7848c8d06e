"""The wheel: it carries the env configs and the shipped checkpoint, and, installed outside the
repository, runs ``vertiport_v1.env()`` and the ``marl-vertiport`` command."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kwargs)
    assert result.returncode == 0, f"{cmd}: {result.stdout[-2000:]}\n{result.stderr[-2000:]}"
    return result


def test_wheel_runs_outside_the_repository(tmp_path):
    # Build from a copy of the sources, so the build leaves nothing in the checkout.
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for package in ("marl_vertiport", "agents"):
        shutil.copytree(ROOT / package, src / package, ignore=skip)
    wheels = tmp_path / "wheels"
    _run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
          "-w", str(wheels), str(src)])
    (wheel,) = wheels.glob("marl_vertiport-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {p.name for p in (ROOT / "marl_vertiport" / "configs").glob("*.yaml")}
    assert {f"marl_vertiport/configs/{n}" for n in shipped} <= names
    assert "agents/checkpoints/gcn_default.pt" in names

    # Install it alone into a folder that comes first on the path; run from elsewhere.
    site = tmp_path / "site"
    _run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site),
          str(wheel)])
    env = {**os.environ, "PYTHONPATH": str(site)}
    work = tmp_path / "elsewhere"
    work.mkdir()
    code = ("import marl_vertiport, agents; from marl_vertiport import vertiport_v1; "
            "e = vertiport_v1.env(); e.reset(seed=0); "
            "print(marl_vertiport.__file__); print(agents.__file__); print(e.unwrapped.config.name)")
    out = _run([sys.executable, "-c", code], cwd=work, env=env).stdout.split()
    assert out[0].startswith(str(site)) and out[1].startswith(str(site)), out
    assert out[2] == "paper"
    script = site / "bin" / "marl-vertiport"
    demo = _run([sys.executable, str(script), "demo", "--config", "small",
                 "--episodes", "1"], cwd=work, env=env)
    assert "episode 0 (seed 0)" in demo.stdout
