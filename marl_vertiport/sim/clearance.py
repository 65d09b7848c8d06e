"""The ATC's separation check (``atc.separation_check``, rules v1): clearances reserve space, not
time, so no clearance can bring two aircraft within ``safety.min_separation_m``.

Every vehicle inside the airspace holds a *reservation*, the protected volume of what it was
cleared for: a vehicle in flight, its leg from where its current segment began to the leg's end;
a vehicle at rest (on a pad, at a hover spot, holding, out of service), the point where it
stands; a vehicle returning from its destination, its holding slot. A volume is a chain of
straight segments, each vertical or level (the only legs the simulator flies), each extended
behind its start by ``atc.along_track_margin_m``: a vehicle moves only along its segment, and a
reversing gust pushes it back along it no farther than that margin (:mod:`~.motion` stops it
there, as the ground stops a climb pushed down).

Two volumes are *clear* when every pair of their segments is at least
``H = min_separation_m + atc.horizontal_buffer_m`` apart horizontally (the distance of their
plan-view projections) or has altitude ranges at least ``V = min_separation_m +
atc.vertical_buffer_m`` apart. Any point of one is then at least the separation from any point
of the other (a 3-D distance is at least its horizontal and its vertical part), at every moment,
however gusts delay either vehicle. With the shipped numbers (H = 4 m, V = 3.5 m) flight layers
4 m apart are clear of each other, and so is a move at 4 m of a vehicle parked below it (3.85 m),
while a climb or a descent needs 4 m of plan-view distance from everything at its altitudes.

A clearance (a take-off, a move to a node, an avoidance climb, a hover spot for an arriving
vehicle, a holding slot) is legal only if its volume clears every other vehicle's reservation;
the action mask says so (:meth:`Clearance.mask_reasons` says why an action is masked).

Procedures (docs/reward-and-safety.md, section 7.4): departures climb on their pad to
``flight.departure_altitude_m``, above every other flow, and leave on their destination's
bearing; arrivals come back at ``flight.arrival_altitude_m`` to a holding slot of their own on
the airspace boundary, and go from there to a hover spot when the route clears. Emergency
landings come down outside every reserved volume. A clearance may follow a departure
(:mod:`~.trailing`); the avoidance climb is :mod:`~.avoidance`'s.
"""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.energy import local_route
from marl_vertiport.sim.layout import HOVER_SPOT
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, LEADING_ACTIONS, OUT_OF_SERVICE, TAXIING,
)
from marl_vertiport.sim.volumes import (
    MEMO_MAX, TaxiMoves, Volume, VolumeMemo, box, boxes_apart, shared_memo, volume,
    volumes_clear,
)

_NODES = LEADING_ACTIONS
_FLYING = (TAXIING, DEPARTING, ARRIVING)
#: Steps of flight a reservation is released by at a time, behind a vehicle.
_QUANTUM_STEPS = 2
_EPS = 1e-9


class Clearance:
    """Reservations and the separation check of :class:`~marl_vertiport.sim.core.VertiportSim`
    (a part of it: the state it reads and keeps is the simulator's)."""

    # ---------------------------------------------------------------- fixed for the env
    def _init_clearance(self) -> None:
        atc, lay = self.cfg.atc, self.layout
        self.sep_check = atc.separation_check
        self.trail = self.sep_check and atc.trail_departures
        self.trail_chains = atc.trail_chains
        sep = self.cfg.safety.min_separation_m
        self.clear_h_m = sep + atc.horizontal_buffer_m
        self.clear_v_m = sep + atc.vertical_buffer_m
        self.margin_m = atc.along_track_margin_m
        self.arrival_alt_m = self.cfg.flight.arrival_altitude_m
        # Holding slots: evenly spaced just inside the boundary, at the arrival altitude,
        # starting on the bearing of the first destination.
        radius = lay.airspace_radius_m * (1.0 - 1e-3)
        fit = max(1, int(2.0 * math.pi * radius // (2.0 * self.clear_h_m)))
        count = atc.holding_slots or max(self.n, len(lay.destination_xy_m))
        count = min(count, fit)
        d0 = lay.destination_xy_m[0]
        phase = math.atan2(d0[1], d0[0])
        angles = phase + 2.0 * math.pi * np.arange(count) / count
        self.slot_pos = np.column_stack([radius * np.cos(angles), radius * np.sin(angles),
                                         np.full(count, self.arrival_alt_m)])
        self.slot_pos.setflags(write=False)
        self._hover_nodes = np.flatnonzero(lay.node_type == HOVER_SPOT)
        # Memos of pure functions of the geometry and of reservations (never episode state),
        # shared with every simulator of the same geometry in this process.
        fl = self.cfg.flight
        key = (lay.node_xy_m.tobytes(), lay.node_type.tobytes(), lay.node_z_m.tobytes(),
               lay.destination_xy_m.tobytes(), lay.airspace_radius_m, fl.hover_altitude_m,
               fl.departure_altitude_m, self.arrival_alt_m, self.margin_m, self.clear_h_m,
               self.clear_v_m, self.park_z_m, tuple(fl.avoid_altitudes_m), self.step_len_m)
        memo = self._memo = shared_memo(key) if self.sep_check else VolumeMemo()
        self._memo_gen = memo.gen
        self._volume_ids, self._volumes, self._boxes = memo.volume_ids, memo.volumes, memo.boxes
        self._node_ok, self._trip_ok = memo.node_ok, memo.trip_ok
        self._taxi_volumes, self._trip_volumes = memo.taxi_volumes, memo.trip_volumes
        self._trip_boxes = memo.trip_boxes
        self._taxi_move_sets = memo.taxi_moves

    def _check_memo(self) -> None:
        """Name this simulator's reservations again if another simulator emptied the shared
        memos since (the ids it holds name entries of the emptied table)."""
        if self._memo_gen != self._memo.gen:
            self._memo_gen = self._memo.gen
            self._reintern()

    def _trim_memos(self) -> None:
        """Empty the memos when they have grown large (at the start of a day; every simulator
        sharing them names its reservations again before it next uses them)."""
        if self._memo.size() >= MEMO_MAX:
            self._memo.clear()
        self._memo_gen = self._memo.gen

    def _intern(self, vol: Volume) -> int:
        """A small int naming ``vol`` (the key of the memos)."""
        vid = self._volume_ids.get(vol)
        if vid is None:
            vid = len(self._volumes)
            self._volume_ids[vol] = vid
            self._volumes.append(vol)
            self._boxes.append(box(vol))
        return vid

    # ---------------------------------------------------------------- reservations
    def _reserve(self, v: int) -> None:
        """Set vehicle ``v``'s reservation from its state (rules v1 only)."""
        if not self.sep_check:
            return
        s = self.status.item(v)
        on_leg = s in _FLYING and self.has_target.item(v)
        if not on_leg:
            self.release_at[v] = None  # nothing to release: not on a leg inside the airspace
        if s == OUT_OF_SERVICE and math.hypot(self.pos[v, 0], self.pos[v, 1]) \
                >= self.layout.airspace_radius_m:
            self.reservation[v] = -1  # down outside the airspace
            self.reserved[v] = None
            return
        if s == AWAY:
            slot = self.slot_of.item(v)
            if slot < 0:
                self.reservation[v] = -1
                self.reserved[v] = None
                return
            vid = self._point_id(self.slot_pos[slot])
        elif on_leg:
            # A leg's volume and its quick release test, memoised by the leg's points.
            s0, t0 = self.seg_from[v].tolist(), self.target[v].tolist()
            points = s0 + t0
            for w in self.routes[v]:
                points += w.tolist()
            key = tuple(points)
            done = self._memo.flights.get(key)
            if done is None:
                vol = volume(s0, [t0] + self.routes[v], self.margin_m, self.park_z_m)
                self._note_release(v, s0, t0)
                done = (self._intern(vol), self.release_at[v])
                self._memo.flights[key] = done
            vid, self.release_at[v] = done
        else:
            vid = self._point_id(self.pos[v])
        self.reservation[v] = vid
        self.reserved[v] = self._volumes[vid]

    def _note_release(self, v: int, s: list[float], t: list[float]) -> None:
        """Keep, for the quick test of :meth:`_advance_reservation`, vehicle ``v``'s segment
        start ``s``, its unit direction to the target ``t`` and the distance along it below
        which nothing is released yet."""
        ux, uy, uz = t[0] - s[0], t[1] - s[1], t[2] - s[2]
        seg_m = math.sqrt(ux * ux + uy * uy + uz * uz)
        if seg_m <= _EPS:
            self.release_at[v] = None
            return
        # Also kept: the direction unnormalised and the length, for the release itself.
        self.release_at[v] = (s[0], s[1], s[2], ux / seg_m, uy / seg_m, uz / seg_m,
                              _QUANTUM_STEPS * self.step_len_m - 1e-6, ux, uy, uz, seg_m)

    def _advance_reservation(self, v: int, p: list[float], t: list[float]) -> None:
        """Release the part of vehicle ``v``'s current segment it has flown: its start moves up
        to the last whole two steps of flight (``2 x step_len_m``, so that the volumes of a day
        repeat and their tests are memoised) the vehicle has passed, never back. ``p``: its position,
        ``t``: its target. Called only once the quick test of ``release_at[v]`` has passed (the
        motion's loop makes it, :meth:`Motion._process_arrivals`)."""
        if self.status.item(v) not in _FLYING:
            return
        sx, sy, sz, _, _, _, _, ux, uy, uz, seg_m = self.release_at[v]
        s = (sx, sy, sz)  # where the segment began (seg_from), as noted
        along = ((p[0] - s[0]) * ux + (p[1] - s[1]) * uy + (p[2] - s[2]) * uz) / seg_m
        quantum = _QUANTUM_STEPS * self.step_len_m
        steps = math.floor(along / quantum + 1e-9)
        if steps < 1:
            return
        # The volume after a release depends only on the volume before it, where the segment
        # began (a climb's volume, cut at the ground, does not say) and the quanta flown.
        key = (self.reservation.item(v), s[0], s[1], s[2], steps)
        done = self._memo.releases.get(key)
        if done is None:
            f = steps * quantum / seg_m
            start = (round(s[0] + f * ux, 9), round(s[1] + f * uy, 9), round(s[2] + f * uz, 9))
            # Only the first segment of the volume changes (the rest is the leg ahead).
            vol = volume(start, (t,), self.margin_m, self.park_z_m) + self.reserved[v][1:]
            self._note_release(v, list(start), t)
            done = (start, self._intern(vol), vol, self.release_at[v])
            self._memo.releases[key] = done
        start, vid, vol, quick = done
        self.seg_from[v] = start
        self.reservation[v] = vid
        self.reserved[v] = vol
        self.release_at[v] = quick

    def _reintern(self) -> None:
        """Name the reservations of a restored state in this sim's memo table."""
        for v, vol in enumerate(self.reserved):
            self.reservation[v] = -1 if vol is None else self._intern(vol)

    def _others(self, v: int, trail: bool) -> list[tuple[int, int]]:
        """``(vehicle, reservation id)`` of every reservation a clearance of vehicle ``v`` must
        clear: all but ``v``'s own, and, with ``trail`` and ``atc.trail_departures``, but those
        of departing vehicles (a clearance may follow them, :meth:`_note_leaders`); without
        ``atc.trail_chains``, only of departing vehicles that follow none themselves."""
        res = self.reservation.tolist()
        if trail and self.trail:
            status = self.status.tolist()
            chains, leaders = self.trail_chains, self.leaders
            return [(u, rid) for u, rid in enumerate(res)
                    if u != v and rid >= 0
                    and (status[u] != DEPARTING or (not chains and leaders[u]))]
        return [(u, rid) for u, rid in enumerate(res) if u != v and rid >= 0]

    def _other_rids(self, v: int, trail: bool) -> tuple[int, ...]:
        """The reservation ids of :meth:`_others`, as a tuple (a memo key)."""
        return tuple([rid for _, rid in self._others(v, trail)])

    def _blockers(self, vol: Volume, v: int, trail: bool = False) -> list[int]:
        """The vehicles other than ``v`` whose reservation ``vol`` does not clear (of those
        :meth:`_others` names)."""
        h, vv = self.clear_h_m, self.clear_v_m
        bx = box(vol)
        out = []
        for u, rid in self._others(v, trail):
            if boxes_apart(bx, self._boxes[rid], h, vv):
                continue
            if not volumes_clear(vol, self._volumes[rid], h, vv):
                out.append(u)
        return out

    def _clear_of_others(self, vol: Volume, v: int, trail: bool = False) -> bool:
        return not self._blockers(vol, v, trail)

    def _point_id(self, xyz: np.ndarray) -> int:
        """The interned volume of the point ``xyz`` (a vehicle at rest, a holding slot)."""
        return self._route_id(xyz, ("at",), tuple)

    def _route_id(self, start: np.ndarray, key: tuple, route) -> int:
        """The interned volume of a flight from ``start`` along ``route()`` (a callable, called
        only the first time), memoised by ``start`` and ``key``."""
        full = (float(start[0]), float(start[1]), float(start[2])) + key
        vid = self._memo.route_ids.get(full)
        if vid is None:
            waypoints = route()
            vid = self._intern(volume(start, waypoints, self.margin_m if waypoints else 0.0,
                                      self.park_z_m))
            self._memo.route_ids[full] = vid
        return vid

    # ---------------------------------------------------------------- candidate volumes
    def _taxi_volume_list(self, node: int) -> list[Volume]:
        """Volumes of the moves from ``node`` to every node (index: the target)."""
        vols = self._taxi_volumes.get(node)
        if vols is None:
            start = self._node_pos[node]
            hover = self.cfg.flight.hover_altitude_m
            vols = [volume(start, local_route(start, self._node_pos[k], hover), self.margin_m,
                           self.park_z_m) if k != node else () for k in range(self.layout.n_nodes)]
            self._taxi_volumes[node] = vols
        return vols

    def _taxi_moves(self, node: int) -> TaxiMoves:
        """The moves from ``node`` for the separation check (memoised)."""
        moves = self._taxi_move_sets.get(node)
        if moves is None:
            moves = self._taxi_move_sets[node] = TaxiMoves(self._taxi_volume_list(node))
        return moves

    def _trip_volume(self, node: int, dest: int) -> Volume:
        """Volume of a take-off from port ``node`` for destination ``dest``."""
        key = (node, dest)
        vol = self._trip_volumes.get(key)
        if vol is None:
            vol = volume(self._node_pos[node], self._departure_route(node, dest), self.margin_m,
                         self.park_z_m)
            self._trip_volumes[key] = vol
        return vol

    def _departure_route(self, node: int, dest: int) -> list[np.ndarray]:
        alt = self.cfg.flight.departure_altitude_m
        x, y = self.layout.node_xy_m[node]
        exit_xy = self.layout.boundary_point(self.layout.node_xy_m[node],
                                             self.layout.destination_xy_m[dest])
        return [np.array([x, y, alt]), np.array([exit_xy[0], exit_xy[1], alt])]

    def _arrival_route(self, start: np.ndarray, node: int) -> list[np.ndarray]:
        """Waypoints of an arrival to hover spot ``node``: across at the arrival altitude, then
        down to the spot (no second point where the spot is at that altitude)."""
        nx, ny = self.layout.node_xy_m[node]
        spot = self._node_pos[node].copy()
        if abs(spot[2] - self.arrival_alt_m) <= _EPS:
            return [spot]
        return [np.array([nx, ny, self.arrival_alt_m]), spot]

    def _node_clearances(self, node: int, rid: int, targets: list[int]) -> list[int]:
        """By node (``P`` ints): at each node of ``targets``, 1 where the move from ``node`` to it
        clears reservation ``rid``, else 0; other entries are those tested before (-1: never)."""
        key = (node, rid)
        ok = self._node_ok.get(key)
        if ok is None:
            ok = self._node_ok[key] = [-1] * self.layout.n_nodes
            need = targets
        else:
            need = [k for k in targets if ok[k] < 0]
        if need:
            self._taxi_moves(node).fill(ok, need, self._volumes[rid], self._boxes[rid],
                                        self.clear_h_m, self.clear_v_m)
        return ok

    def _trip_clearance(self, node: int, dest: int, rid: int) -> bool:
        key = (node, dest, rid)
        ok = self._trip_ok.get(key)
        if ok is None:
            vol, h, vv = self._trip_volume(node, dest), self.clear_h_m, self.clear_v_m
            bx = self._trip_boxes.get((node, dest))
            if bx is None:
                bx = self._trip_boxes[(node, dest)] = box(vol)
            ok = boxes_apart(bx, self._boxes[rid], h, vv) or volumes_clear(
                vol, self._volumes[rid], h, vv)
            self._trip_ok[key] = ok
        return ok

    # ---------------------------------------------------------------- the check
    def _apply_separation_check(self, v: int, mask: np.ndarray, on_ground: bool) -> None:
        """Clear, in ``mask`` (of vehicle ``v`` at rest on a node), the take-off and the node
        moves whose volume does not clear another vehicle's reservation. Only the moves the
        mask still allows are tested (the free nodes the energy check clears); the memo of a
        situation keeps what has been tested of it: ``[keep, tested nodes]``, ``keep`` 1 where
        the check keeps the action as it is."""
        node = self.node.item(v)
        dest = self.dest.item(v) if on_ground else -1
        key = (node, dest, self._other_rids(v, trail=True))
        entry = self._memo.masks.get(key)
        if entry is None:
            keep = np.ones(self.actions.n, dtype=np.int8)
            trip = on_ground
            for rid in key[2]:
                trip = trip and self._trip_clearance(node, dest, rid)
            if not trip:  # a hovering vehicle has no take-off to keep
                keep[self.actions.takeoff] = 0
            entry = self._memo.masks[key] = [keep, set()]
        keep, tested = entry
        n = self.layout.n_nodes
        need = [k for k in np.flatnonzero(mask[_NODES:_NODES + n]).tolist() if k not in tested]
        if need:
            tested.update(need)
            nodes = keep[_NODES:_NODES + n]
            for rid in key[2]:
                ok = self._node_clearances(node, rid, need)
                if not all(ok[k] for k in need):
                    for k in need:
                        if not ok[k]:
                            nodes[k] = 0
                    need = [k for k in need if ok[k]]
                    if not need:
                        break
        mask &= keep

    def _ids_clear(self, a: int, b: int) -> bool:
        """Whether interned volumes ``a`` and ``b`` are clear of each other."""
        h, vv = self.clear_h_m, self.clear_v_m
        return (boxes_apart(self._boxes[a], self._boxes[b], h, vv)
                or volumes_clear(self._volumes[a], self._volumes[b], h, vv))

    def _pair_clear(self, a: int, b: int) -> bool:
        """:meth:`_ids_clear`, memoised per pair."""
        key = (a, b) if a < b else (b, a)
        ok = self._memo.pair_ok.get(key)
        if ok is None:
            ok = self._ids_clear(a, b)
            self._memo.pair_ok[key] = ok
        return ok

    # ---------------------------------------------------------------- arrivals
    def _free_slot(self, v: int) -> int:
        """Rules v1: the free holding slot nearest to the bearing of vehicle ``v`` (away, at its
        destination) whose point clears every reservation, or -1."""
        taken = set(self.slot_of[self.slot_of >= 0].tolist())
        # The slots depend on the fleet size, which the shared memo's geometry does not fix.
        here = (self.pos.item(v, 0), self.pos.item(v, 1), len(self.slot_pos))
        order = self._memo.slot_order.get(here)
        if order is None:
            d = np.hypot(self.slot_pos[:, 0] - here[0], self.slot_pos[:, 1] - here[1])
            order = self._memo.slot_order[here] = np.argsort(d, kind="stable").tolist()
        ids = self._memo.slot_ids.get(here[2])
        if ids is None:
            ids = self._memo.slot_ids[here[2]] = [self._point_id(p) for p in self.slot_pos]
        rids = self._other_rids(v, trail=False)
        for k in order:
            if k in taken:
                continue
            if all(self._pair_clear(ids[k], rid) for rid in rids):
                return k
        return -1

    def _nearest_clear_hover_spot(self, v: int, spots: list[int]) -> int:
        """The first of the free hover spots ``spots`` (nearest first) whose arrival route from
        vehicle ``v``'s position clears every other reservation, or -1 (memoised)."""
        pos = self.pos[v]
        rids = self._other_rids(v, trail=True)
        key = (*pos.tolist(), rids, *spots)
        node = self._memo.spots.get(key)
        if node is None:
            node = -1
            pair_clear = self._pair_clear
            for k in spots:
                rid = self._route_id(pos, ("arrival", k), lambda k=k: self._arrival_route(pos, k))
                if all(pair_clear(rid, r) for r in rids):
                    node = k
                    break
            self._memo.spots[key] = node
        return node

    def _landing_point_clear(self, v: int, xy: np.ndarray) -> bool:
        """Rules v1: whether vehicle ``v`` may come down at ``xy`` in an emergency landing: its
        fall from where it is to the ground clears every other reservation."""
        fall = ((float(xy[0]), float(xy[1]), float(xy[0]), float(xy[1]), self.park_z_m,
                 max(float(self.pos[v, 2]), self.park_z_m)),)
        return self._clear_of_others(fall, v)

    # ---------------------------------------------------------------- explanations
    def mask_reasons(self, v: int) -> dict[int, str]:
        """Why each masked action of vehicle ``v`` is masked now: action index -> one of
        ``"status"`` (not an action of its status), ``"occupancy"`` (the node is held by another
        vehicle, or is where it stands), ``"energy"`` (the energy check), ``"separation"`` (the
        separation check; the vehicles in the way follow: ``"separation: evtol_2, evtol_3"``)."""
        if self.sep_check:
            self._check_memo()
        mask = self.action_mask(v)
        acts, p = self.actions, self.layout.n_nodes
        reasons: dict[int, str] = {}
        s = self.status.item(v)
        node = self.node.item(v)
        at_rest_kind = self._fixed_masks[s] is None and s not in (TAXIING, DEPARTING, ARRIVING)
        for a in np.flatnonzero(mask == 0).tolist():
            if not at_rest_kind:
                reasons[a] = "status"
                if a == acts.avoid and self.sep_check and s in (TAXIING, DEPARTING, ARRIVING):
                    reasons[a] = self._avoid_reason(v)
                continue
            if a in (acts.continue_, acts.avoid):
                reasons[a] = "status"
            elif a == acts.takeoff:
                reasons[a] = "status" if not self._is_port[node] else self._why(
                    v, a, self._trip_volume(node, self.dest.item(v)) if self.sep_check else None)
            elif _NODES <= a < _NODES + p:
                k = a - _NODES
                if s != HOVERING and not self._is_port[k]:  # a vehicle on a pad goes to pads only
                    reasons[a] = "status"
                elif self.node_occupant[k] != -1 or k == node:
                    reasons[a] = "occupancy"
                else:
                    reasons[a] = self._why(
                        v, a, self._taxi_volume_list(node)[k] if self.sep_check else None)
            else:  # stay, masked by the energy check (a hovering vehicle that must land)
                reasons[a] = "energy"
        return reasons

    def _why(self, v: int, action: int, vol: Volume | None) -> str:
        atc = self.cfg.atc
        if atc.energy_check and self.flight_energy_pct(v, action) >= \
                self.battery.item(v) - atc.energy_reserve_pct:
            return "energy"
        if vol is not None:
            blockers = self._blockers(vol, v, trail=True)
            if blockers:
                return "separation: " + ", ".join(f"evtol_{u}" for u in blockers)
        return "energy"  # the hover-hold rule of the energy check
