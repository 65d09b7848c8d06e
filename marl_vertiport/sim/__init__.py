"""The simulator core, no RL library: one module per concept of the paper.

``layout`` (ports, charging ports, hover spots, destinations), ``physics`` (pybullet flight),
``battery`` (eq. 1), ``schedule`` (flight plans and delays), ``reward`` (eq. 2), ``safety`` (the
conflict probe, eqs. 3-5, and the separation flown), ``uncertainty`` (case 2's draws),
``energy`` (the battery a planned flight needs), ``geometry``, ``schema`` (statuses, features,
actions), ``metrics``; ``core`` holds the state of a day and the order of a step."""

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.geometry import closest_approach
from marl_vertiport.sim.layout import Layout

__all__ = ["Layout", "VertiportSim", "closest_approach"]
