"""What must hold after every step of any day, whatever the actions and the uncertainties:
the checks of the property-based tests and of the soak (``python -m agents.studies.soak``)."""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import AWAY


def reward_bound(sim: VertiportSim) -> float:
    """The largest absolute reward of a step: the term magnitude times the sum of the weights."""
    rw = sim.cfg.reward
    return rw.term_magnitude * (rw.takeoff_weight + rw.landing_weight + rw.battery_weight
                                + rw.delay_weight + rw.safety_weight)


def violations(sim: VertiportSim, reward: float | None = None) -> list[str]:
    """The invariants that fail now (empty when all hold): the step's reward finite and within
    :func:`reward_bound`; batteries in [0, 100]; no vehicle inside the airspace below the
    ground; no two vehicles on the ground inside one another; each port or hover spot held by
    at most one vehicle, consistently both ways; every vehicle's mask int8 and non-empty."""
    out = []
    if reward is not None and not (math.isfinite(reward) and abs(reward) <= reward_bound(sim) + 1e-9):
        out.append(f"reward {reward} outside [-{reward_bound(sim)}, {reward_bound(sim)}]")
    bad = np.flatnonzero((sim.battery < 0.0) | (sim.battery > 100.0) | ~np.isfinite(sim.battery))
    out += [f"evtol_{v}: battery {sim.battery[v]}" for v in bad]
    inside = sim.status != AWAY
    low = np.flatnonzero(inside & (sim.pos[:, 2] < sim.park_z_m - 1e-9))
    out += [f"evtol_{v}: below the ground (z {sim.pos[v, 2]:.3f} m)" for v in low]
    size = sim.cfg.flight.vehicle_size_m
    ground = np.flatnonzero(inside & (sim.pos[:, 2] <= sim.park_z_m + 1e-6))
    for i, a in enumerate(ground):
        for b in ground[i + 1:]:
            if (np.abs(sim.pos[a, :2] - sim.pos[b, :2]) < size - 1e-6).all():
                out.append(f"evtol_{a} and evtol_{b}: inside one another on the ground")
    held = sim.node[sim.node >= 0].tolist()
    if len(set(held)) != len(held):
        out.append(f"one node held by two vehicles: {sorted(held)}")
    for node, occupant in enumerate(sim.node_occupant.tolist()):
        if occupant != -1 and sim.node[occupant] != node:
            out.append(f"node {node}: occupant evtol_{occupant} holds node {sim.node[occupant]}")
    for v in range(sim.n):
        mask = sim.action_mask(v)
        if mask.dtype != np.int8 or not mask.any():
            out.append(f"evtol_{v}: mask {mask.dtype} with {int(mask.sum())} legal actions")
    return out
