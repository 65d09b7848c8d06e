"""Separation, predicted and flown.

The ATC's conflict probe (paper eqs. 3-5) predicts, for the vehicles in transit inside the
airspace, which pairs will come closer than ``safety.min_separation_m`` on their planned legs;
the acting vehicle's flag sets the safety term S of the reward. The separation flown is
measured after the step's motion: the closest approach of every pair over the step (swept, so a
pass between two positions is caught), new losses of separation, and new contacts of the
engine's bodies.
"""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.geometry import swept_min_distance
from marl_vertiport.sim.safety import (
    SCALAR_PAIRS_MAX, conflicting_pairs, planned_velocity, swept_distances_m,
)
from marl_vertiport.sim.schema import AWAY, IN_TRANSIT_INSIDE


class Separation:
    """The conflict probe and the separation measurement of
    :class:`~marl_vertiport.sim.core.VertiportSim` (a part of it)."""

    def _refresh_conflicts(self) -> None:
        """The ATC's conflict probe, for every vehicle in transit inside the airspace: its
        planned horizontal velocity (toward its current waypoint at cruise speed, 0 while it
        climbs or descends) and whether it is in a predicted conflict (the paper's check).

        A pair conflicts when both fly legs less than the separation apart in altitude, their
        planned 2-D paths come within the separation distance of each other (our reading of
        "intersecting paths" for vehicles with a footprint), and their closest approach lies
        ahead (``t_min >= 0``) and within the separation distance (eqs. 3-4). The relation is
        symmetric; the safety term of a step uses the acting vehicle's flag.
        """
        if self._any_conflict_probe:
            self.plan_vel_xy.fill(0.0)
            self.conflict.fill(False)
        cand = [v for v, (s, t) in enumerate(zip(self.status.tolist(), self.has_target.tolist()))
                if t and IN_TRANSIT_INSIDE[s]]
        self._any_conflict_probe = bool(cand)
        if not cand:
            return
        speed = self.cfg.flight.cruise_speed_mps
        pos, target, routes = self.pos.tolist(), self.target.tolist(), self.routes
        vel, start, end = {}, {}, {}
        for v in cand:
            start[v] = (pos[v][0], pos[v][1])
            vel[v] = planned_velocity(start[v], (target[v][0], target[v][1]), speed)
            last = routes[v][-1] if routes[v] else None
            end[v] = (target[v][0], target[v][1]) if last is None else (last.item(0), last.item(1))
            self.plan_vel_xy[v] = vel[v]
        if len(cand) < 2:
            return
        for a, b in conflicting_pairs(cand, start, end, vel, self.leg_alt.tolist(),
                                      self.cfg.safety.min_separation_m):
            self.conflict[a] = self.conflict[b] = True

    def _initial_separation_m(self) -> float:
        """Smallest centre distance of two vehicles in the airspace now (inf for fewer than two)."""
        inside = [v for v in range(self.n) if self.status.item(v) != AWAY and v not in self._gone]
        best = float("inf")
        pos = self.pos.tolist()
        for i, a in enumerate(inside):
            for b in inside[i + 1:]:
                d = math.dist(pos[a], pos[b])
                if d < best:
                    best = d
        return best

    def _measure_separation(self, status: list[int], start: list[list[float]],
                            end: list[list[float]]) -> tuple[int, int]:
        """New losses of separation (swept over the step) and new engine contacts.

        Args:
            status: per vehicle, its status code during the step, ``N`` ints.
            start, end: per vehicle, its position at the start and at the end of the step's
                motion, ``N`` lists ``[x, y, z]``.

        Only pairs with a vehicle that flew inside the airspace this step can change; pairs of
        vehicles that stood still keep their state.
        """
        movers = [v for v in self._moved if end[v] != start[v] and status[v] != AWAY]
        n = self.n
        if n < 2 or not movers:
            return 0, 0
        present = [s != AWAY for s in status]
        for v in self._gone:  # rules v1: down outside the airspace
            present[v] = False
        mover_set = set(movers)
        sep = self.cfg.safety.min_separation_m
        # Every pair of present vehicles with a mover in it, in sorted order: as lists for a
        # few, as index arrays for many (then only the pairs closer than the separation or
        # touching distance are kept as lists, with the least distance of all).
        pairs: list[tuple[int, int]] | None
        if len(movers) == 1:
            m = movers[0]
            pairs = [(o, m) if o < m else (m, o) for o in range(n) if o != m and present[o]]
        elif n * (n - 1) // 2 <= SCALAR_PAIRS_MAX:
            pairs = [(a, b) for a in range(n) if present[a] for b in range(a + 1, n)
                     if present[b] and (a in mover_set or b in mover_set)]
        else:
            live = np.array(present)
            moving = np.zeros(n, dtype=bool)
            moving[movers] = True
            pi, pj = self._pair_i, self._pair_j
            keep = live[pi] & live[pj] & (moving[pi] | moving[pj])
            pi, pj = pi[keep], pj[keep]
            pairs = list(zip(pi.tolist(), pj.tolist())) if len(pi) <= SCALAR_PAIRS_MAX else None
        if pairs is not None:
            if not pairs:
                return 0, 0
            dmin = swept_distances_m(self.prev_pos, self.pos, pairs, start, end)
            closest = min(dmin)
        else:
            dist = swept_min_distance(self.prev_pos, self.pos, pi, pj)
            closest = float(dist.min())
            near = np.flatnonzero((dist < sep) | (dist <= self._touch_m))
            pairs = list(zip(pi[near].tolist(), pj[near].tolist()))
            dmin = dist[near].tolist()
        losses = {pair for pair, d in zip(pairs, dmin) if d < sep}
        kept = {pair for pair in self.sep_state if pair[0] not in mover_set and pair[1] not in mover_set}
        new_losses = len(losses - self.sep_state)
        self.sep_state = kept | losses
        self.metrics.separation_losses += new_losses
        if closest < self.metrics.min_separation_m:
            self.metrics.min_separation_m = closest
        # Engine contacts: those left at the end of the step, and those resolved within its
        # substeps (a deflected body and a vehicle that came within touching distance of it).
        contacts = set(self.physics.contact_pairs())
        if contacts or closest < self._near_m:
            # Each step's near passes and contacts are resolved afresh: the engine caches, for a
            # pair of bodies close enough to be checked, its contact points and the last
            # separating axis, and would warm-start the next step from them, a state no snapshot
            # holds, so a restored world would step differently.
            self.physics.forget_contacts()
        if self._deflected:
            deflected = set(self._deflected)
            contacts.update(pair for pair, d in zip(pairs, dmin)
                            if d <= self._touch_m and (pair[0] in deflected or pair[1] in deflected))
        kept = {pair for pair in self.contact_state
                if pair[0] not in mover_set and pair[1] not in mover_set}
        new_contacts = len(contacts - self.contact_state)
        self.contact_state = kept | contacts
        self.metrics.contacts += new_contacts
        return new_losses, new_contacts
