"""The vertiport's fixed geometry as arrays, derived once from the config."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from marl_vertiport.config import EnvConfig
from marl_vertiport.sim.geometry import dot

#: Node types of the vertiport graph (feature ``type`` of a port node).
NORMAL_PORT, CHARGING_PORT, HOVER_SPOT = 0, 1, 2


def ring(count: int, radius_m: float, phase_rad: float = 0.0) -> np.ndarray:
    """``count`` points evenly spaced on a circle, shape ``(count, 2)``."""
    angles = phase_rad + 2.0 * np.pi * np.arange(count) / max(count, 1)
    return np.stack([radius_m * np.cos(angles), radius_m * np.sin(angles)], axis=1)


@dataclass(frozen=True)
class Layout:
    """Positions and types of the vertiport nodes and the destinations.

    Attributes:
        node_xy_m: ``(P, 2)`` ground positions of normal ports, charging ports, hover spots.
        node_type: ``(P,)`` int, one of NORMAL_PORT, CHARGING_PORT, HOVER_SPOT.
        node_z_m: ``(P,)`` altitude of a vehicle's centre when it sits on / hovers at the node.
        destination_xy_m: ``(D, 2)`` destinations outside the airspace.
        airspace_radius_m: radius of the controlled airspace.
    """

    node_xy_m: np.ndarray
    node_type: np.ndarray
    node_z_m: np.ndarray
    destination_xy_m: np.ndarray
    airspace_radius_m: float
    n_normal: int
    n_charging: int
    n_hover: int

    @property
    def n_ports(self) -> int:
        return self.n_normal + self.n_charging

    @property
    def n_nodes(self) -> int:
        return self.n_ports + self.n_hover

    @classmethod
    def from_config(cls, cfg: EnvConfig) -> Layout:
        lay = cfg.layout
        normal = np.asarray(lay.normal_ports_xy_m, dtype=float).reshape(-1, 2)
        charging = np.asarray(lay.charging_ports_xy_m, dtype=float).reshape(-1, 2)
        if lay.hover_spots_xy_m:
            hover = np.asarray(lay.hover_spots_xy_m, dtype=float).reshape(-1, 2)
        else:
            # Rotated by half a step: no spot on the +x axis, where the ring would start.
            hover = ring(lay.hover_ring_count, lay.hover_ring_radius_m, np.pi / max(lay.hover_ring_count, 1))
        if lay.destinations_xy_m:
            dest = np.asarray(lay.destinations_xy_m, dtype=float).reshape(-1, 2)
        else:
            dest = ring(lay.destination_ring_count, lay.destination_ring_radius_m, np.pi / 2)
        node_xy = np.concatenate([normal, charging, hover], axis=0)
        node_type = np.concatenate([
            np.full(len(normal), NORMAL_PORT), np.full(len(charging), CHARGING_PORT),
            np.full(len(hover), HOVER_SPOT),
        ]).astype(np.int64)
        park_z = cfg.flight.vehicle_height_m / 2.0
        node_z = np.where(node_type == HOVER_SPOT, cfg.flight.hover_altitude_m, park_z)
        for arr in (node_xy, node_z, node_type, dest):
            arr.setflags(write=False)
        return cls(node_xy, node_type, node_z, dest, lay.airspace_radius_m,
                   len(normal), len(charging), len(hover))

    def boundary_point(self, inside_xy: np.ndarray, outside_xy: np.ndarray) -> np.ndarray:
        """Where the straight line from ``inside_xy`` to ``outside_xy`` crosses the airspace
        boundary, shape ``(2,)``."""
        d = outside_xy - inside_xy
        a = dot(d, d)
        b = 2.0 * dot(inside_xy, d)
        c = dot(inside_xy, inside_xy) - self.airspace_radius_m ** 2
        t = (-b + np.sqrt(max(b * b - 4 * a * c, 0.0))) / (2 * a)
        return inside_xy + t * d
