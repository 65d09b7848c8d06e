"""What must hold after every step of any day, whatever the actions and the uncertainties: the
one checker of the tests (``tests/sim/test_invariants.py``), the property-based tests and the fuzz
target (``make fuzz``) and the soak (``make soak``)."""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import AWAY, OUT_OF_SERVICE


def reward_bound(sim: VertiportSim) -> float:
    """The largest absolute reward of a step: the term magnitude times the sum of the weights."""
    rw = sim.cfg.reward
    return rw.term_magnitude * (rw.takeoff_weight + rw.landing_weight + rw.battery_weight
                                + rw.delay_weight + rw.safety_weight)


def violations(sim: VertiportSim, reward: float | None = None) -> list[str]:
    """The invariants that fail now (empty when all hold): the step's reward finite and within
    :func:`reward_bound`; batteries in [0, 100]; no more landings below the reserve than
    completed trips; the clock at ``steps x minutes_per_step``; no
    vehicle inside the airspace below the ground; no two vehicles on the ground inside one
    another; each port or hover spot held by at most one vehicle, consistently both ways; a
    vehicle at rest on its node exactly there; a vehicle away outside the airspace (its
    boundary, less a rounding of 0.2 %); every vehicle's mask int8 and non-empty; under the
    separation check (rules v1), no loss of separation or contact counted and no two vehicles
    in the airspace closer than the separation."""
    out = []
    if not math.isclose(sim.minute, sim.step_count * sim.minutes_per_step, rel_tol=1e-12, abs_tol=1e-9):
        out.append(f"clock at minute {sim.minute} after {sim.step_count} steps")
    if reward is not None and not (math.isfinite(reward) and abs(reward) <= reward_bound(sim) + 1e-9):
        out.append(f"reward {reward} outside [-{reward_bound(sim)}, {reward_bound(sim)}]")
    bad = np.flatnonzero((sim.battery < 0.0) | (sim.battery > 100.0) | ~np.isfinite(sim.battery))
    out += [f"evtol_{v}: battery {sim.battery[v]}" for v in bad]
    m = sim.metrics
    if not 0 <= m.reserve_violations <= m.completed_trips:
        out.append(f"{m.reserve_violations} landings below the reserve in {m.completed_trips} "
                   f"completed trips")
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
    at_rest = np.flatnonzero(~sim.has_target & (sim.node >= 0) & (sim.status != OUT_OF_SERVICE))
    for v in at_rest:
        node = sim.node[v]
        if np.abs(sim.pos[v] - sim._node_pos[node]).max() > 1e-6:
            out.append(f"evtol_{v}: at rest {sim.pos[v].round(4).tolist()} off its node {node} "
                       f"{sim._node_pos[node].round(4).tolist()}")
    away = np.flatnonzero(~inside)
    radius = sim.layout.airspace_radius_m * (1 - 2e-3)
    out += [f"evtol_{v}: away {float(np.hypot(*sim.pos[v, :2])):.3f} m from the centre, inside "
            f"the airspace" for v in away if np.hypot(*sim.pos[v, :2]) < radius]
    if sim.sep_check:  # rules v1: separation by construction
        sep = sim.cfg.safety.min_separation_m
        if sim.metrics.separation_losses or sim.metrics.contacts:
            out.append(f"{sim.metrics.separation_losses} losses of separation and "
                       f"{sim.metrics.contacts} contacts under the separation check")
        there = [v for v in np.flatnonzero(inside).tolist()
                 if np.hypot(*sim.pos[v, :2]) < sim.layout.airspace_radius_m]
        for i, a in enumerate(there):
            for b in there[i + 1:]:
                d = float(np.sqrt(((sim.pos[a] - sim.pos[b]) ** 2).sum()))
                if d < sep:
                    out.append(f"evtol_{a} and evtol_{b}: {d:.3f} m apart, under the "
                               f"separation of {sep:g} m")
    for v in range(sim.n):
        mask = sim.action_mask(v)
        if mask.dtype != np.int8 or not mask.any():
            out.append(f"evtol_{v}: mask {mask.dtype} with {int(mask.sum())} legal actions")
    return out
