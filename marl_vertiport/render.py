"""Frames of the vertiport from pybullet's headless TinyRenderer (shared by both envs)."""

from __future__ import annotations

import numpy as np

from marl_vertiport.sim.core import VertiportSim

#: Default frame size in pixels (width, height).
FRAME_SIZE = (480, 360)


def draw_scenery(sim: VertiportSim) -> None:
    """Add the visual-only ground, ports, hover spots and airspace ring (once)."""
    lay = sim.layout
    sim.physics.build_scenery(lay.node_xy_m, lay.node_type, lay.node_z_m, lay.airspace_radius_m)


def render_frame(sim: VertiportSim, width: int = FRAME_SIZE[0], height: int = FRAME_SIZE[1]) -> np.ndarray:
    """An RGB frame of the airspace, shape ``(height, width, 3)`` uint8.

    Bodies in the engine sit where the simulator says, so nothing is synchronised here;
    vehicles outside the airspace are out of view (their bodies wait below ground).
    """
    draw_scenery(sim)
    lay = sim.layout
    return sim.physics.camera_image(width, height, (0.0, 0.0, 0.0),
                                    distance_m=lay.airspace_radius_m * 2.2)
