"""marl_vertiport: air-traffic control at an Urban Air Mobility vertiport.

- :mod:`marl_vertiport.vertiport_v0`: the PettingZoo AEC env (one agent per eVTOL).
- ``gymnasium.make("marl_vertiport/Vertiport-v0")``: the fully centralised single-agent env.
- :mod:`marl_vertiport.graph`: observations to torch-geometric batches.
- :mod:`marl_vertiport.sim`: the simulator core (no RL library inside).
"""

from __future__ import annotations

import gymnasium

from marl_vertiport.config import ConfigError, EnvConfig, load_config
from marl_vertiport.sim.core import IllegalActionError
from marl_vertiport.sim.geometry import closest_approach

__all__ = ["ConfigError", "EnvConfig", "IllegalActionError", "closest_approach", "load_config",
           "vertiport_v0"]

__version__ = "0.1.0"

if "marl_vertiport/Vertiport-v0" not in gymnasium.registry:
    # No order-enforcing or checker wrappers: gymnasium's wrappers do not forward the env's own
    # methods (state(), action_masks()), and the env enforces the order itself.
    gymnasium.register(id="marl_vertiport/Vertiport-v0", entry_point="marl_vertiport.gym_env:VertiportEnv",
                       order_enforce=False, disable_env_checker=True)


def __getattr__(name: str):
    # Lazy, so that `import marl_vertiport` does not pull in PettingZoo.
    if name == "vertiport_v0":
        import importlib

        return importlib.import_module("marl_vertiport.vertiport_v0")
    raise AttributeError(name)
