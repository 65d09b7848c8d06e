"""What an import loads: the simulator core and the env package load no RL or deep-learning
library, and the Gymnasium id is registered in every order of the imports."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("gymnasium", "pettingzoo", "torch", "torch_geometric", "rsl_rl", "tensordict")


def run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip()


@pytest.mark.parametrize("module", ["marl_vertiport.sim", "marl_vertiport",
                                    "marl_vertiport.config", "marl_vertiport.graph"])
def test_the_core_and_the_package_load_no_rl_library(module):
    loaded = run(f"import sys, {module}\nprint(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    assert loaded == "[]"


@pytest.mark.parametrize("code", [
    "import marl_vertiport, gymnasium",            # ours first: registered when Gymnasium loads
    "import gymnasium, marl_vertiport",            # Gymnasium first: registered at once
    "import gymnasium",                            # none of ours: the module:id form imports it
])
def test_the_gymnasium_id_is_registered_in_any_order_of_imports(code):
    env_id = ("marl_vertiport:marl_vertiport/Vertiport-v1" if code == "import gymnasium"
              else "marl_vertiport/Vertiport-v1")
    shown = run(f"{code}\nenv = gymnasium.make({env_id!r})\nobs, info = env.reset(seed=0)\n"
                f"print(type(env.unwrapped).__name__, info['agent'])")
    assert shown == "VertiportEnv evtol_0"


def test_the_pettingzoo_env_loads_pettingzoo_and_not_torch():
    loaded = run("import sys\nfrom marl_vertiport import vertiport_v1\n"
                 f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    assert loaded == "['gymnasium', 'pettingzoo']"
