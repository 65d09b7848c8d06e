"""Vertiport air-traffic control, PettingZoo AEC env, version 0 (superseded by
:mod:`marl_vertiport.vertiport_v1`, whose docstring describes the env; kept bit for bit for
results made with it).

The same agents, spaces, state, rewards and episode end as version 1; only the rules differ:
no separation check (the ATC clears any flight the paper's table I and the energy check allow)
and arrivals at the transit altitude, straight back to the boundary on their destination's
radial. ``atc.separation_check`` and ``flight.arrival_altitude_m`` are set to those rules
whatever the config says (:func:`marl_vertiport.config.with_rules`).

Version history:
    * v1: :mod:`marl_vertiport.vertiport_v1`: the separation check, its airspace procedures and
      the calibrated cruise drain (2026-11-26).
    * v0: initial release (2026-11-22). Its episodes are the simulator's at a790a05
      (2026-11-26), kept bit for bit since; ``parallel_env()`` added (2026-11-28). CHANGELOG.md,
      "Rules versions", lists what a v0 user may still notice.
"""

from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv

from marl_vertiport.aec_env import OrderEnforcing, VertiportAEC, reset_agent_dicts
from marl_vertiport.parallel_env import VertiportParallel
from marl_vertiport.config import EnvConfig

__all__ = ["OrderEnforcing", "env", "parallel_env", "parallel_raw_env", "raw_env",
           "reset_agent_dicts"]


def env(config: str | EnvConfig | dict | None = None, render_mode: str | None = None,
        **overrides: Any) -> AECEnv:
    """The AEC env with PettingZoo's order-enforcing wrapper."""
    return OrderEnforcing(raw_env(config=config, render_mode=render_mode, **overrides))


class raw_env(VertiportAEC):
    """Unwrapped AEC env; see the module docstring."""

    RULES = 0
    metadata = dict(VertiportAEC.metadata, name="vertiport_v0")


class parallel_raw_env(VertiportParallel):
    """The Parallel env (one parallel step = one ATC turn; :mod:`marl_vertiport.parallel_env`)."""

    RULES = 0
    metadata = dict(VertiportParallel.metadata, name="vertiport_v0")


def parallel_env(config: str | EnvConfig | dict | None = None, render_mode: str | None = None,
                 **overrides: Any) -> VertiportParallel:
    """The PettingZoo Parallel env: the same simulator, one parallel step per ATC turn; the
    agents whose turn it is not may only wait (:mod:`marl_vertiport.parallel_env`)."""
    return parallel_raw_env(config=config, render_mode=render_mode, **overrides)
