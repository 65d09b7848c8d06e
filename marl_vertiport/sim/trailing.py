"""Trailing a departure (rules v1, ``atc.trail_departures``): a flight may be cleared behind a
departing vehicle whose reservation it does not clear, and the simulator holds it, each step,
wherever its next step of flight would not clear that reservation.

Why it is safe: a departure never waits for a vehicle cleared after it and leaves the airspace,
and its reservation only shrinks until then (released behind it, :mod:`~.clearance`), so space
that a follower's step finds clear of it stays clear. A follower's step is tested with the
margin behind its position, where a reversing gust may push it. Each clearance is numbered; a
vehicle yields only to clearances older than its own, so no two vehicles wait for each other
and every wait ends when the departure ahead has gone (every other reservation the follower's
clearance had to clear, :meth:`Clearance._apply_separation_check`).

Why it is there: a departure holds the column over its pad through its climb and its
outbound leg until it leaves; with whole-leg reservations alone the pad it left and every
way across its path stay closed that long (docs/reward-and-safety.md, section 7.4).
"""

from __future__ import annotations

from marl_vertiport.sim.schema import DEPARTING
from marl_vertiport.sim.volumes import box, boxes_apart, volume, volumes_clear


class Trailing:
    """Leaders, followers and holds of :class:`~marl_vertiport.sim.core.VertiportSim` (a part of
    it: the state it reads and keeps is the simulator's)."""

    def _note_leaders(self, v: int) -> None:
        """Vehicle ``v`` was just cleared (its reservation set): number the clearance and keep,
        as its leaders, the departing vehicles whose reservation its own does not clear (a
        clearance that follows them, ``atc.trail_departures``). A vehicle only ever yields to
        clearances older than its own, so no two vehicles wait for each other."""
        self._clear_count += 1
        self.clear_seq[v] = self._clear_count
        rid = self.reservation.item(v)
        if not self.trail or rid < 0:
            self.leaders[v] = ()
            return
        status = self.status.tolist()
        if DEPARTING not in status:
            self.leaders[v] = ()
            return
        self.leaders[v] = tuple(
            u for u, r in enumerate(self.reservation.tolist())
            if u != v and r >= 0 and status[u] == DEPARTING and not self._pair_clear(rid, r))

    def _must_hold(self, v: int, p: tuple, q: tuple) -> bool:
        """Whether vehicle ``v``, about to fly from ``p`` to ``q`` this step, must hold where it
        is instead: the sweep of the step (with the margin behind ``p``) does not clear the
        reservation of a leader. Leaders whose reservation now clears ``v``'s, or that hold a
        newer clearance than ``v``'s, or none, are dropped. A leader's reservation only
        shrinks, so space the sweep finds clear stays clear."""
        own = self.reservation.item(v)
        seq = self.clear_seq
        memo = self._memo.hold
        keep, hold, sweep = [], False, None
        for u in self.leaders[v]:
            rid = self.reservation.item(u)
            if rid < 0 or seq.item(u) > seq.item(v) or self._pair_clear(own, rid):
                continue
            keep.append(u)
            if hold:
                continue
            key = (p, q, rid)
            blocked = memo.get(key)
            if blocked is None:
                if sweep is None:
                    sweep = volume(p, (q,), self.margin_m, self.park_z_m)
                    bx = box(sweep)
                h, vv = self.clear_h_m, self.clear_v_m
                blocked = not (boxes_apart(bx, self._boxes[rid], h, vv)
                               or volumes_clear(sweep, self._volumes[rid], h, vv))
                memo[key] = blocked
            hold = blocked
        self.leaders[v] = tuple(keep)
        return hold
