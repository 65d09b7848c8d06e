"""A vehicle's life through the day, as the ATC's clearances and its own flight move it along:
taxiing between nodes, departure to the airspace boundary and on to its destination, the return
and the re-entry, the hover spot it is sent to (or the hold at the boundary while none is free),
the avoidance manoeuvre (a climb to a free avoidance layer, paper section II-C), landing and the
next flight plan, and the emergency landing of a vehicle whose battery is empty in the air
(out of service for the rest of the day, set down clear of every vehicle on the ground).
"""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.energy import local_route
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, NO_OPERATION, ON_CHARGER, ON_PORT, OUT_OF_SERVICE,
    PENDING_LANDING, PENDING_TAKEOFF, TAXIING,
)


class Lifecycle:
    """Node occupancy, routes and status changes of :class:`~marl_vertiport.sim.core.VertiportSim`
    (a part of it: the state it changes is the simulator's)."""

    def _occupy(self, v: int, node: int) -> None:
        self.node[v] = node
        self.node_occupant[node] = v

    def _release(self, v: int) -> None:
        node = self.node[v]
        if node >= 0 and self.node_occupant[node] == v:
            self.node_occupant[node] = -1
        self.node[v] = -1

    def _set_route(self, v: int, waypoints: list[np.ndarray], leg_alt_m: float) -> None:
        self.target[v] = waypoints[0]
        self.routes[v] = list(waypoints[1:])
        self.has_target[v] = True
        self.leg_alt[v] = leg_alt_m
        self.seg_from[v] = self.pos[v]
        self._reserve(v)
        if self.trail:
            self._note_leaders(v)

    def _local_route(self, v: int, node: int) -> list[np.ndarray]:
        """Route at hover altitude from the vehicle to vertiport node ``node``."""
        return local_route(self.pos[v], self._node_pos[node], self.cfg.flight.hover_altitude_m)

    def _complete_operation(self, v: int, now: float) -> None:
        self.completed_delay[v] += self.schedule.lateness_min(now, self.pending_time.item(v))
        self.pending_kind[v] = NO_OPERATION
        self.delay[v] = 0.0

    def _start_departure(self, v: int) -> None:
        alt = self.cfg.flight.departure_altitude_m
        x, y, _ = self.pos[v]
        dest_xy = self.layout.destination_xy_m[self.dest[v]]
        exit_xy = self.layout.boundary_point(self.pos[v, :2], dest_xy)
        self._release(v)
        self.status[v] = DEPARTING
        self._set_route(v, [np.array([x, y, alt]), np.array([exit_xy[0], exit_xy[1], alt])], alt)
        self.physics.make_dynamic(v)

    def _avoid(self, v: int) -> None:
        """Climb to the lowest avoidance layer no other vehicle uses and fly the rest of the
        leg there. Hold position for this step instead when no horizontal travel is left (the
        final descent onto a spot) or when every layer is taken."""
        if self.avoid_layer[v] >= 0 or not self.has_target[v]:
            return
        if self.sep_check:  # rules v1: the lowest layer whose volume clears (the mask's)
            plan = self._avoid_plan(v)
            if plan is None:
                return
            k, route = plan
            if k < 0:
                self.routes[v].insert(0, self.target[v].copy())
                self.target[v] = self.pos[v].copy()
                self._reserve(v)
                return
            self.avoid_layer[v] = k
            self._set_route(v, route, self.cfg.flight.avoid_altitudes_m[k])
            return
        waypoints = [self.target[v]] + self.routes[v]
        horizontal = [w for w in waypoints if np.hypot(*(w[:2] - self.pos[v, :2])) > 1e-9]
        used = set(self.avoid_layer[self.avoid_layer >= 0].tolist())
        layers = self.cfg.flight.avoid_altitudes_m
        free = [k for k in range(len(layers)) if k not in used]
        if not free or not horizontal:
            # The route resumes next step from where the vehicle holds now.
            self.routes[v].insert(0, self.target[v].copy())
            self.target[v] = self.pos[v].copy()
            return
        k = free[0]
        alt = layers[k]
        self.avoid_layer[v] = k
        route = self._avoid_route(v, alt, waypoints, horizontal)
        self._set_route(v, route, alt)

    def _finish_leg(self, v: int) -> int:
        s = self.status[v]
        lay, cfg = self.layout, self.cfg
        self.avoid_layer[v] = -1
        if s == TAXIING or s == ARRIVING:
            node = self.node[v]
            self.pos[v] = self._node_pos[node]
            self.physics.make_static(v, self.pos[v])
            if lay.node_type[node] == HOVER_SPOT:
                self.status[v] = HOVERING
                self._reserve(v)
                return 0
            self.status[v] = ON_CHARGER if lay.node_type[node] == CHARGING_PORT else ON_PORT
            self._reserve(v)
            if self.landing_cleared[v]:
                self.landing_cleared[v] = False
                self.pending_kind[v] = PENDING_TAKEOFF
                trips = self.rng if self.draws is None else self.draws.trips[v]
                self.pending_time[v] = self.schedule.takeoff_after_landing_min(
                    trips, self.minute + self.minutes_per_step)
                self.dest[v] = int(trips.integers(len(lay.destination_xy_m)))
                self.metrics.completed_trips += 1
                self._trip_ends.append(v)  # its landing reserve is read after the step's drain
                return 1
            return 0
        if s == DEPARTING:
            self.status[v] = AWAY
            self.returning[v] = False
            self.physics.make_absent(v)
            d = lay.destination_xy_m[self.dest[v]]
            # Rules v1: out of the airspace, down from the departure layer to the arrival
            # altitude on the way to the destination (one straight leg), so the way back
            # starts level; rules v0 fly both at the transit altitude.
            alt = self.arrival_alt_m if self.sep_check else self.pos[v, 2]
            self._set_route(v, [np.array([d[0], d[1], alt])], alt)
            return 0
        if s == AWAY and not self.returning[v]:
            self.returning[v] = True
            if self.sep_check:  # rules v1: to a holding slot of its own, or wait out here
                self._head_for_slot(v)
                return 0
            entry = lay.boundary_point(np.zeros(2), self.pos[v, :2])
            # Aim slightly inside the boundary so the re-entry is unambiguous.
            entry = entry * (1.0 - 1e-3)
            alt = cfg.flight.arrival_altitude_m
            self._set_route(v, [np.array([entry[0], entry[1], alt])], alt)
            return 0
        if s == AWAY:
            self.status[v] = ARRIVING
            self.returning[v] = False
            self.pending_kind[v] = PENDING_LANDING
            self.pending_time[v] = self.schedule.landing_min(self.minute + self.minutes_per_step)
            self.physics.make_static(v, self.pos[v])
            self._assign_hover_spot(v)
            return 0
        return 0

    def _head_for_slot(self, v: int) -> None:
        """Rules v1: send vehicle ``v``, away at its destination, to the nearest free holding
        slot that clears every reservation (reserved from now), or let it wait where it is."""
        slot = self._free_slot(v)
        if slot < 0:
            self._waiting_outside.add(v)
            self.has_target[v] = False
            return
        self._waiting_outside.discard(v)
        self.slot_of[v] = slot
        self._set_route(v, self._route_to_slot(v, slot), self.arrival_alt_m)

    def _route_to_slot(self, v: int, slot: int) -> list[np.ndarray]:
        """Waypoints from vehicle ``v`` outside the airspace to holding slot ``slot``, at the
        arrival altitude: around the airspace (at least 5 % outside its boundary, 30 degrees of
        bearing at most a leg, so no leg cuts inside it), then straight in on the slot's
        bearing. Memoised by where it is and the slot (the arrays are read-only)."""
        x, y, z = self.pos[v].tolist()
        key = (x, y, z, slot, len(self.slot_pos))
        route = self._memo.slot_routes.get(key)
        if route is None:
            route = self._memo.slot_routes[key] = self._slot_route(x, y, z, slot)
        return list(route)

    def _slot_route(self, x: float, y: float, z: float, slot: int) -> tuple[np.ndarray, ...]:
        """:meth:`_route_to_slot` from ``(x, y, z)``, as read-only arrays."""
        alt = self.arrival_alt_m
        radius = max(math.hypot(x, y), 1.05 * self.layout.airspace_radius_m)
        sx, sy = float(self.slot_pos[slot, 0]), float(self.slot_pos[slot, 1])
        here, there = math.atan2(y, x), math.atan2(sy, sx)
        turn = (there - here + math.pi) % (2.0 * math.pi) - math.pi
        legs = max(1, math.ceil(abs(turn) / (math.pi / 6.0)))
        route = [np.array([radius * math.cos(here + turn * k / legs),
                           radius * math.sin(here + turn * k / legs), alt])
                 for k in range(1 if legs else 0, legs + 1)]
        # Back from a destination on the slot's bearing, the first point is where it is.
        route = [p for p in route if abs(p[0] - x) + abs(p[1] - y) + abs(p[2] - z) > 1e-9]
        route.append(self.slot_pos[slot].copy())
        for p in route:
            p.setflags(write=False)
        return tuple(route)

    def _assign_hover_spot(self, v: int) -> None:
        """Send an arriving vehicle to the free hover spot nearest to it, or hold it (rules
        v1: among the spots whose arrival route clears every reservation; it holds in its
        slot)."""
        lay = self.layout
        free = np.flatnonzero((lay.node_type == HOVER_SPOT) & (self.node_occupant == -1))
        node = -1
        if free.size:  # nearest first (ties: in node order)
            d = np.linalg.norm(lay.node_xy_m[free] - self.pos[v, :2], axis=1)
            spots = free[np.argsort(d, kind="stable")].tolist()
            node = self._nearest_clear_hover_spot(v, spots) if self.sep_check else spots[0]
        if node < 0:
            if v not in self._holding:  # holds at the boundary until a spot frees up
                self._holding.add(v)
                self._reserve(v)  # where it holds (a holding vehicle does not move)
            return
        self._holding.discard(v)
        self.slot_of[v] = -1
        self._occupy(v, node)
        self._set_route(v, self._arrival_route(self.pos[v], node),
                        self.cfg.flight.arrival_altitude_m)
        self.physics.make_dynamic(v)

    def _take_out_of_service(self, v: int) -> None:
        """Battery depleted in the air: emergency landing where it is, out of service for the
        rest of the day. Rules v0: if it comes down within two vehicle sizes of a free port it
        takes the nearest such port, so nothing lands on top of it; rules v1: it comes down
        clear of every reservation instead. It never comes down on or inside a vehicle on the
        ground (:meth:`_clear_landing_xy`). A late
        operation it leaves undone keeps its lateness (at the end of this step) in the metrics."""
        if self.pending_kind[v] != NO_OPERATION:
            self.completed_delay[v] += self.schedule.lateness_min(
                self.minute + self.minutes_per_step, self.pending_time.item(v))
        self.has_target[v] = False
        self.routes[v] = []
        self.avoid_layer[v] = -1
        self.landing_cleared[v] = False
        self.pending_kind[v] = NO_OPERATION
        self._release(v)
        inside = self.status[v] != AWAY
        self.status[v] = OUT_OF_SERVICE
        if self.sep_check:  # rules v1: it gives up its slot and never leaves the ground
            self.slot_of[v] = -1
            self._holding.discard(v)
            self._waiting_outside.discard(v)
        if inside:
            self.pos[v, 2] = self.park_z_m
            if not self.sep_check:  # rules v0: onto a free port close by, if there is one
                d = np.linalg.norm(self.layout.node_xy_m - self.pos[v, :2], axis=1)
                near = np.flatnonzero((d < self.cfg.flight.vehicle_size_m * 2) & self._is_port
                                      & (self.node_occupant == -1))
                if near.size:
                    self._occupy(v, int(near[np.argmin(d[near])]))
            self.pos[v, :2] = self._clear_landing_xy(v)
            self.physics.make_static(v, self.pos[v])
        elif self.sep_check:  # down outside the airspace: out of the ATC's picture, as if away
            self._gone.add(v)
        self._reserve(v)

    def _clear_landing_xy(self, v: int) -> np.ndarray:
        """Where vehicle ``v`` comes down in an emergency landing: straight below it, or, when
        that would put it within touching distance of a vehicle on the ground, the nearest point
        clear of all of them (on rings of one touching distance around it, 12 bearings each,
        inside the airspace), so that it never lands on or inside another vehicle."""
        here = self.pos[v, :2].copy()
        grounded = [u for u in range(self.n) if u != v and self.pos[u, 2] <= self.park_z_m + 1e-6
                    and self.status[u] != AWAY]
        if not grounded and not self.sep_check:
            return here
        others = self.pos[grounded, :2] if grounded else np.full((1, 2), np.inf)
        clear = self._touch_m
        if np.linalg.norm(others - here, axis=1).min() >= clear and (
                not self.sep_check or self._landing_point_clear(v, here)):
            return here
        radius = self.layout.airspace_radius_m
        bearings = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
        for ring in range(1, 4 * self.n + 2 + (8 * int(radius) if self.sep_check else 0)):
            points = here + ring * clear * np.column_stack([np.cos(bearings), np.sin(bearings)])
            ok = (np.linalg.norm(points[:, None] - others[None], axis=2).min(axis=1) >= clear) \
                & (np.linalg.norm(points, axis=1) < radius)
            for k in np.flatnonzero(ok).tolist():
                if not self.sep_check or self._landing_point_clear(v, points[k]):
                    return points[k]
        return here  # pragma: no cover - a full airspace; cannot happen with a valid layout
