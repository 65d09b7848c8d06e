"""The simulator core: layout, flight physics, vehicles, schedules, reward. No RL library."""

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.geometry import closest_approach
from marl_vertiport.sim.layout import Layout

__all__ = ["Layout", "VertiportSim", "closest_approach"]
