"""The battery a planned flight needs, from the battery model and the motion model.

A vehicle flies each leg of a route straight toward the leg's end at ``step_len_m`` per step and
stops there: the rest of that step is not carried over to the next leg. A step in which it moves
at least ``min_cruise_distance_m`` costs ``cruise_pct_per_m`` of the battery config
(``cruise_drain_pct_per_m * cruise_drain_scale``) per metre moved; a shorter step costs ``hover_drain_pct``. These functions add that up for a route without gusts, which is
what the ATC's energy check (``atc.energy_check``) and the stranded-vehicle metric compare a
battery against. A flight whose whole route costs ``E`` is finished with battery ``b`` if
``b > E`` (a vehicle that reaches 0 % while airborne is out of service).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from marl_vertiport.config import BatteryConfig, EnvConfig
from marl_vertiport.sim.geometry import length
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT, Layout


def leg_steps(length_m: float, step_len_m: float) -> int:
    """Steps to fly one straight leg of ``length_m`` metres (a vehicle stops at a leg's end)."""
    if length_m <= 1e-9:
        return 0
    return max(math.ceil(length_m / step_len_m - 1e-9), 1)


def leg_energy_pct(length_m: float, step_len_m: float, battery: BatteryConfig) -> float:
    """Battery (percent) to fly one straight leg of ``length_m`` metres."""
    steps = leg_steps(length_m, step_len_m)
    if steps == 0:
        return 0.0
    last_m = length_m - (steps - 1) * step_len_m

    def cost(moved_m: float) -> float:
        if moved_m >= battery.min_cruise_distance_m:
            return battery.cruise_pct_per_m * moved_m
        return battery.hover_drain_pct

    return (steps - 1) * cost(step_len_m) + cost(last_m)


def _leg_lengths_m(start: Sequence[float], waypoints: Sequence[Sequence[float]]
                   ) -> Iterator[float]:
    """Length (m) of each leg from ``start`` through ``waypoints`` (each ``(x, y, z)`` metres)."""
    here = np.asarray(start, dtype=float)
    for w in waypoints:
        w = np.asarray(w, dtype=float)
        yield length(w - here)
        here = w


def route_steps(start: Sequence[float], waypoints: Sequence[Sequence[float]],
                step_len_m: float) -> int:
    """Steps to fly from ``start`` through ``waypoints`` (each ``(x, y, z)`` metres)."""
    total = 0
    for leg_m in _leg_lengths_m(start, waypoints):
        total += leg_steps(leg_m, step_len_m)
    return total


def route_energy_pct(start: Sequence[float], waypoints: Sequence[Sequence[float]],
                     step_len_m: float, battery: BatteryConfig) -> float:
    """Battery (percent) to fly from ``start`` through ``waypoints`` (each ``(x, y, z)`` metres)."""
    total = 0.0
    for leg_m in _leg_lengths_m(start, waypoints):
        total += leg_energy_pct(leg_m, step_len_m, battery)
    return total


def local_route(start: Sequence[float], target: Sequence[float], hover_altitude_m: float
                ) -> list[np.ndarray]:
    """Waypoints of a move inside the vertiport (a taxi, a landing, a move between hover spots)
    from ``start`` ``(x, y, z)`` to a node at ``target`` ``(x, y, z)``: up or down to the hover
    altitude, across at that altitude, then down to the node (each leg only where needed)."""
    x, y, z = (float(c) for c in start)
    nx, ny, nz = (float(c) for c in target)
    route = []
    if abs(z - hover_altitude_m) > 1e-9:
        route.append(np.array([x, y, hover_altitude_m]))
    route.append(np.array([nx, ny, hover_altitude_m]))
    if abs(nz - hover_altitude_m) > 1e-9:
        route.append(np.array([nx, ny, nz]))
    return route


class FlightEnergy:
    """Battery (percent, without gusts) of the flights an ATC clears, fixed by the layout.

    Attributes:
        hop_pct: ``(P, P)``: from node ``i`` (a port or a hover spot) to node ``k`` (a taxi, a
            landing or a move between hover spots); 0 on the diagonal.
        trip_pct: ``(ports, D)``: a take-off from port ``i`` for destination ``d``: the climb to
            the departure altitude, out to the airspace boundary, to the destination, back to the
            boundary on its radial at the arrival altitude (without the way around to a holding
            slot, which the reserve covers), to the hover spot nearest to the re-entry point, and the
            landing on the charging port nearest to that spot (straight from the boundary to the
            nearest charging port in a layout without hover spots).
        trip_steps: ``(ports, D)``: the steps of flight of that trip, without gusts.
    """

    def __init__(self, cfg: EnvConfig, layout: Layout) -> None:
        fl, bat = cfg.flight, cfg.battery
        step = fl.cruise_speed_mps * fl.flight_seconds_per_step
        node_pos = np.column_stack([layout.node_xy_m, layout.node_z_m])
        hover_alt = fl.hover_altitude_m

        def cost(start: np.ndarray, node: int) -> float:
            return route_energy_pct(start, local_route(start, node_pos[node], hover_alt), step, bat)

        p = layout.n_nodes
        self.hop_pct = np.array([[0.0 if i == k else cost(node_pos[i], k) for k in range(p)]
                                 for i in range(p)]).reshape(p, p)
        chargers = np.flatnonzero(layout.node_type == CHARGING_PORT).tolist()
        spots = np.flatnonzero(layout.node_type == HOVER_SPOT)
        alt, back = fl.departure_altitude_m, fl.arrival_altitude_m
        trip = np.zeros((layout.n_ports, len(layout.destination_xy_m)))
        trip_steps = np.zeros(trip.shape, dtype=int)
        for i in range(layout.n_ports):
            start = node_pos[i]
            for d, dest_xy in enumerate(layout.destination_xy_m):
                exit_xy = layout.boundary_point(start[:2], dest_xy)
                entry_xy = layout.boundary_point(np.zeros(2), dest_xy) * (1.0 - 1e-3)
                route = [(start[0], start[1], alt), (*exit_xy, alt), (*dest_xy, back), (*entry_xy, back)]
                if spots.size:
                    h = int(spots[np.argmin(np.linalg.norm(layout.node_xy_m[spots] - entry_xy, axis=1))])
                    route += [(*layout.node_xy_m[h], back), node_pos[h]]
                    c = min(chargers, key=lambda c: self.hop_pct[h, c])
                    land = self.hop_pct[h, c]
                    land_steps = route_steps(node_pos[h], local_route(node_pos[h], node_pos[c], hover_alt),
                                            step)
                else:
                    here = np.array([*entry_xy, back])
                    c = min(chargers, key=lambda c: cost(here, c))
                    land = cost(here, c)
                    land_steps = route_steps(here, local_route(here, node_pos[c], hover_alt), step)
                trip[i, d] = route_energy_pct(start, route, step, bat) + land
                trip_steps[i, d] = route_steps(start, route, step) + land_steps
        self.trip_pct = trip
        self.trip_steps = trip_steps
        for arr in (self.hop_pct, self.trip_pct, self.trip_steps):
            arr.setflags(write=False)
