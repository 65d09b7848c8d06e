"""marl_vertiport: air-traffic control at an Urban Air Mobility vertiport.

- :mod:`marl_vertiport.vertiport_v1`: the PettingZoo AEC env (one agent per eVTOL);
  :mod:`marl_vertiport.vertiport_v0` keeps the rules before the separation check.
- ``gymnasium.make("marl_vertiport/Vertiport-v1")`` (``-v0``): the fully centralised
  single-agent env (registered when Gymnasium loads, :mod:`marl_vertiport.registration`).
- :mod:`marl_vertiport.graph`: observations to torch-geometric batches.
- :mod:`marl_vertiport.sim`: the simulator core (no RL library inside).
"""

from __future__ import annotations

from marl_vertiport.config import ConfigError, EnvConfig, load_config
from marl_vertiport.registration import ENV_ID, register_when_gymnasium_loads
from marl_vertiport.sim.core import IllegalActionError
from marl_vertiport.sim.geometry import closest_approach

__all__ = ["ENV_ID", "ConfigError", "EnvConfig", "IllegalActionError", "closest_approach",
           "load_config", "vertiport_v0", "vertiport_v1"]

__version__ = "0.2.0"

# The Gymnasium id, without loading Gymnasium here (marl_vertiport/registration.py).
register_when_gymnasium_loads()


def __getattr__(name: str):
    # Lazy, so that `import marl_vertiport` does not pull in PettingZoo.
    if name in ("vertiport_v0", "vertiport_v1"):
        import importlib

        return importlib.import_module(f"marl_vertiport.{name}")
    raise AttributeError(name)
