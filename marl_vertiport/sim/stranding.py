"""Batteries over a step, and the vehicles they lose.

Every battery drains or charges by the paper's eq. 1 (:mod:`~marl_vertiport.sim.battery`); a
charger that fails this step leaves its vehicle idling. A vehicle whose battery is empty in the
air is lost (an emergency landing, out of service for the day); a vehicle on a normal port is
lost on the ground once no flight it may still be cleared for can bring it back to a charger.
"""

from __future__ import annotations

import numpy as np

from marl_vertiport.sim.layout import CHARGING_PORT
from marl_vertiport.sim.schema import AIRBORNE, ON_CHARGER, ON_PORT, OUT_OF_SERVICE


class Stranding:
    """Battery updates and lost vehicles of :class:`~marl_vertiport.sim.core.VertiportSim`
    (a part of it)."""

    def _update_battery(self, status_during: list[int], failed_nodes: list[int]) -> int:
        """Drain or charge every battery for the step; count the trips of this step that touched
        down below ``battery.landing_reserve_pct`` (their battery after the step's drain); take
        depleted airborne vehicles out of service. Returns the number of depletions.

        Args:
            status_during: per vehicle, its status while it moved this step (``N`` ints).
            failed_nodes: charging nodes whose charger failed this step.

        Scalar per vehicle, as :meth:`_move`: a handful of numpy calls on ``N``-vectors cost
        more than the loop for fleets of a few dozen."""
        failed_charging = ()
        if failed_nodes:
            # A charger that fails this step leaves its vehicle idling on the ground.
            node = self.node.tolist()
            failed_charging = [v for v, s in enumerate(status_during)
                               if s == ON_CHARGER and node[v] in failed_nodes]
        level = self.battery.tolist()
        change = self.battery_model.changes(level, status_during,
                                            zip(self._moved, self._moved_m), failed_charging)
        level = self.battery_model.apply(level, change)
        if self._trip_ends:  # touchdowns of this step, with the battery they land with
            reserve = self.cfg.battery.landing_reserve_pct
            self.metrics.reserve_violations += sum(level[v] < reserve for v in self._trip_ends)
            self._trip_ends.clear()
        empty = [v for v, b in enumerate(level) if b <= 0.0 and AIRBORNE[status_during[v]]]
        self.battery[:] = level
        # The fleet's mean battery for the episode metric. Below 8 values numpy's sum adds them
        # in order, as sum() does; from 8 on it adds pairwise, so it is asked itself.
        total = sum(level) if self.n < 8 else float(np.add.reduce(self.battery))
        self.metrics.battery_sum += total / self.n
        if not empty:
            return 0
        status = self.status.tolist()
        depleted = [v for v in empty if status[v] != OUT_OF_SERVICE]
        end = self.minute + self.minutes_per_step
        for v in depleted:
            self._take_out_of_service(v)
            if not self.lost[v]:
                self.lost[v] = True
                self.lost_min[v] = end
                self.metrics.stranded_air += 1
        self.metrics.battery_depletions += len(depleted)
        return len(depleted)

    def _mark_stranded_on_ground(self) -> int:
        """Mark the vehicles stranded on the ground in this step; returns how many.

        A vehicle on a normal port is stranded when no flight it may still be cleared for can
        bring it back into service: its battery does not cover the hop to a usable charging
        port (one not blocked for the day by a vehicle out of service), or, where no charging
        port is usable, a take-off (:meth:`stranded_threshold_pct`). Idling only drains it
        further, so it stays stranded for the rest of the day."""
        status = self.status.tolist()
        lost = self.lost.tolist()
        candidates = [v for v, s in enumerate(status) if s == ON_PORT and not lost[v]]
        if not candidates:
            return 0
        battery = self.battery.tolist()
        end = self.minute + self.minutes_per_step
        marked = 0
        for v in candidates:
            if battery[v] <= self.stranded_threshold_pct(v):
                self.lost[v] = True
                self.lost_min[v] = end
                marked += 1
        self.metrics.stranded_ground += marked
        return marked

    def stranded_threshold_pct(self, v: int) -> float:
        """Battery (percent) at or below which vehicle ``v``, on the ground at a port, can never
        charge again: the least energy of a hop to a usable charging port (one not occupied by
        a vehicle out of service), or of a take-off where no charging port is usable, plus
        ``atc.energy_reserve_pct`` when the ATC checks energy (the flight is not cleared below
        that). A vehicle on a working charging port is never stranded (0 is returned)."""
        node = self.node.item(v)
        if node < 0 or self.layout.node_type[node] == CHARGING_PORT:
            return 0.0
        occupant, status = self.node_occupant.tolist(), self.status.tolist()
        usable = [c for c in self._charging_nodes.tolist()
                  if occupant[c] < 0 or status[occupant[c]] != OUT_OF_SERVICE]
        hop = self.energy.hop_pct[node]
        need = min(hop[c] for c in usable) if usable else float(self.energy.trip_pct[node, self.dest.item(v)])
        atc = self.cfg.atc
        return float(need + (atc.energy_reserve_pct if atc.energy_check else 0.0))
