"""Vertiport air-traffic control, PettingZoo AEC env, version 0 (superseded by
:mod:`marl_vertiport.vertiport_v1`; kept bit for bit for results made with it).

Description:
    One vertiport with normal ports, charging ports and hover spots, and a fleet of eVTOLs
    flying to destinations outside its airspace and back on flight plans. A centralised ATC
    gives one eVTOL an action per step, in round-robin order (turn ``t`` -> ``evtol_{t mod N}``);
    every vehicle moves every step. Each eVTOL is an agent; one shared policy can act for all.

Agents:
    ``evtol_0 .. evtol_{N-1}``, all present for the whole episode. An agent with no decision to
    make (outside the airspace, out of service) has only a no-op legal.

Action space:
    ``Discrete(4 + P)`` with ``P`` = ports + hover spots: 0 stay still, 1 take off,
    ``2 .. 1+P`` move to / land on vertiport node ``k`` (normal ports, charging ports, then
    hover spots), ``2+P`` continue previous action, ``3+P`` avoid collision.

Observation space:
    ``{"observation": {port_nodes, evtol_nodes, self}, "action_mask": int8}`` (both graphs are
    complete; ``marl_vertiport.graph`` builds their edges); see ``docs/environment.md`` for each
    feature's index and unit.

State:
    ``state()`` is the global, noise-free graph (true positions, velocities, destinations,
    occupants of ports) for a centralised critic; ``state_space`` describes it.

Rewards:
    The paper's weighted sum for the acting eVTOL (take-off, landing, battery, delay, safety);
    other agents get 0 on that step.

Episode end:
    Truncation after ``schedule.episode_steps`` (1440) steps; never termination.

Arguments:
    ``config``: a config object, a dict, a YAML path, or a name in ``configs/env/``;
    ``render_mode``: ``None``, ``"rgb_array"`` or ``"human"``; keyword overrides with dotted
    keys (``**{"uncertainty.wind_gust_prob": 0.1}``) or whole sections.

Version history:
    v0: initial release. No separation check; arrivals at the transit altitude
    (``atc.separation_check`` and ``flight.arrival_altitude_m`` are set to those rules whatever
    the config says, :func:`marl_vertiport.config.with_rules`).
    v1: :mod:`marl_vertiport.vertiport_v1`.
"""


from __future__ import annotations

from typing import Any

from pettingzoo import AECEnv

from marl_vertiport.aec_env import OrderEnforcing, VertiportAEC, reset_agent_dicts
from marl_vertiport.config import EnvConfig

__all__ = ["OrderEnforcing", "env", "raw_env", "reset_agent_dicts"]


def env(config: str | EnvConfig | dict | None = None, render_mode: str | None = None,
        **overrides: Any) -> AECEnv:
    """The AEC env with PettingZoo's order-enforcing wrapper."""
    return OrderEnforcing(raw_env(config=config, render_mode=render_mode, **overrides))


class raw_env(VertiportAEC):
    """Unwrapped AEC env; see the module docstring."""

    RULES = 0
    metadata = dict(VertiportAEC.metadata, name="vertiport_v0")
