"""Vertiport air-traffic control, PettingZoo AEC env, version 1 (the latest).

Description:
    One vertiport with normal ports, charging ports and hover spots, and a fleet of eVTOLs
    flying to destinations outside its airspace and back on flight plans. A centralised ATC
    gives one eVTOL an action per step, in round-robin order (turn ``t`` -> ``evtol_{t mod N}``);
    every vehicle moves every step. Each eVTOL is an agent; one shared policy can act for all.
    The ATC clears a flight only where its protected volume clears every other vehicle's
    (``atc.separation_check``): no clearance brings two aircraft within the separation.

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

Parallel API:
    ``parallel_env()`` is the same simulator as a PettingZoo Parallel env in which one parallel
    step is one ATC turn: every live agent submits an action, the agent whose turn it is
    (``acting_agent``) has its full mask, every other agent only the no-op ``continue``
    (``noop_action``). See :mod:`marl_vertiport.parallel_env`.

Arguments:
    ``config``: a config object, a dict, a YAML path, or a name in ``configs/env/``;
    ``render_mode``: ``None``, ``"rgb_array"`` or ``"human"``; keyword overrides with dotted
    keys (``**{"uncertainty.wind_gust_prob": 0.1}``) or whole sections.

Version history (CHANGELOG.md, "Rules versions", dates every change):
    * v1 (2026-11-26, 5134449): the ATC's separation check and airspace procedures: departures
      at ``flight.departure_altitude_m``, holding slots and arrivals at
      ``flight.arrival_altitude_m``, a reversing gust held inside the protected volume;
      ``info["episode"]`` adds ``min_separation_m`` and ``separation_loss_min``; masks of
      vehicles in flight may drop "avoid collision". Changed after publication, the same day:
      the procedures' altitudes and flows, clearances behind a departure
      (``atc.trail_departures``), and the energy calibration (``battery.cruise_drain_scale``
      0.25, 4c3b34d: every v1 episode changed); later ``reserve_violations`` and
      ``trail_hold_min`` in ``info["episode"]`` (2026-11-26, -27), the Parallel API
      (2026-11-28), ``uncertainty.common_random_numbers`` (2026-11-30, off by default).
    * v0 (2026-11-22): initial release; kept bit for bit as :mod:`marl_vertiport.vertiport_v0`.
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

    RULES = 1
    metadata = dict(VertiportAEC.metadata, name="vertiport_v1")


class parallel_raw_env(VertiportParallel):
    """The Parallel env (one parallel step = one ATC turn; :mod:`marl_vertiport.parallel_env`)."""

    RULES = 1
    metadata = dict(VertiportParallel.metadata, name="vertiport_v1")


def parallel_env(config: str | EnvConfig | dict | None = None, render_mode: str | None = None,
                 **overrides: Any) -> VertiportParallel:
    """The PettingZoo Parallel env: the same simulator, one parallel step per ATC turn; the
    agents whose turn it is not may only wait (:mod:`marl_vertiport.parallel_env`)."""
    return parallel_raw_env(config=config, render_mode=render_mode, **overrides)
