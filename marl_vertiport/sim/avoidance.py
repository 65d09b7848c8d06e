"""The avoidance climb under rules v1 (the paper's avoid-collision action, section II-C, made
safe): the lowest free avoidance layer whose lifted volume clears every other reservation, the
route there, and why it is masked. Both rules fly the route of :meth:`Avoidance._avoid_route`.
"""

from __future__ import annotations

import math

import numpy as np

from marl_vertiport.sim.schema import DEPARTING, STATUS_NAMES

#: A memo's answer for a key it has not seen (its answers include ``None``).
_UNSEEN = object()


class Avoidance:
    """The avoidance layer and route of :class:`~marl_vertiport.sim.core.VertiportSim` (a part
    of it: the state it reads is the simulator's; reservations are :mod:`~.clearance`'s)."""

    def _avoid_layer(self, v: int) -> int | None:
        """Rules v1: the avoidance layer vehicle ``v`` in flight may climb to now (the lowest
        free layer above its leg whose lifted volume clears every other reservation), ``-1``
        for a hold in place (no horizontal travel left: the vehicle stays inside its volume),
        ``None`` when none clears, when it already flies on a layer or holds without a route.

        The test uses the vehicle's reservation lifted to the layer (:meth:`_lifted_id`), which
        holds the avoidance route from anywhere the vehicle may be on its current segment, so
        the answer is memoised per reservation, not per position."""
        layers = self.avoid_layer.tolist()
        if not self.has_target.item(v) or layers[v] >= 0:
            return None
        x, y = self.pos.item(v, 0), self.pos.item(v, 1)
        if math.hypot(self.target.item(v, 0) - x, self.target.item(v, 1) - y) <= 1e-9 and not any(
                math.hypot(w.item(0) - x, w.item(1) - y) > 1e-9 for w in self.routes[v]):
            return -1
        res = self.reservation.tolist()
        memo = self._memo
        # The answer depends on the reservations and the layers in use only (see above).
        key = (v, self.status.item(v) == DEPARTING, self.leg_alt.item(v), tuple(res),
               tuple(layers))
        found = memo.avoid.get(key, _UNSEEN)
        if found is not _UNSEEN:
            return found
        used = {k for k in layers if k >= 0}
        others = [rid for u, rid in enumerate(res) if u != v and rid >= 0]
        found = None
        for k, alt in enumerate(self.cfg.flight.avoid_altitudes_m):
            if k in used or alt <= self.leg_alt.item(v):  # a climb, never a descent
                continue
            lid = self._lifted_id(v, k, alt)
            if all(self._pair_clear(lid, rid) for rid in others):
                found = k
                break
        memo.avoid[key] = found
        return found

    def _lifted_id(self, v: int, k: int, alt: float) -> int:
        """The id of vehicle ``v``'s reservation lifted to avoidance layer ``k`` at ``alt``: its
        current segment as a curtain from the margin below it up to the layer (the climb may
        start anywhere on it), its later level legs at the layer, its later climbs and descents
        as columns reaching the layer with the margin, and, but for a departure, the final
        descent from the layer. The avoidance route from any point of the current segment lies
        inside it."""
        departing = self.status.item(v) == DEPARTING
        key = (self.reservation.item(v), k, departing)
        lid = self._memo.lifted.get(key)
        if lid is None:
            own = self.reserved[v]
            m, floor = self.margin_m, self.park_z_m
            ax, ay, bx, by, zlo, zhi = own[0]
            segs = [(ax, ay, bx, by, max(zlo - m, floor), max(zhi, alt))]
            for t in own[1:]:
                if t[0] != t[2] or t[1] != t[3]:  # a level leg
                    segs.append((t[0], t[1], t[2], t[3], alt, alt))
                else:
                    segs.append((t[0], t[1], t[2], t[3], min(t[4], alt), max(t[5], alt + m)))
            final = (self.routes[v][-1] if self.routes[v] else self.target[v]).tolist()
            if not departing and abs(final[2] - alt) > 1e-9:
                segs.append((final[0], final[1], final[0], final[1], min(final[2], alt),
                             max(final[2], alt) + m))
            lid = self._intern(tuple(segs))
            self._memo.lifted[key] = lid
        return lid

    def _avoid_plan(self, v: int) -> tuple[int, list[np.ndarray]] | None:
        """Rules v1: ``(layer, route)`` of the avoidance climb :meth:`_avoid_layer` clears,
        ``(-1, [])`` for a hold in place, ``None`` when none is cleared."""
        k = self._avoid_layer(v)
        if k is None or k < 0:
            return None if k is None else (-1, [])
        waypoints = [self.target[v]] + self.routes[v]
        horizontal = [w for w in waypoints if math.hypot(w[0] - self.pos[v, 0],
                                                         w[1] - self.pos[v, 1]) > 1e-9]
        return k, self._avoid_route(v, self.cfg.flight.avoid_altitudes_m[k], waypoints,
                                    horizontal)

    def _avoid_route(self, v: int, alt: float, waypoints: list, horizontal: list
                     ) -> list[np.ndarray]:
        final = waypoints[-1]
        new_route = [np.array([self.pos[v, 0], self.pos[v, 1], alt])]
        for w in horizontal:
            new_route.append(np.array([w[0], w[1], alt]))
        if abs(final[2] - alt) > 1e-9 and self.status[v] != DEPARTING:
            new_route.append(final.copy())
        route = [new_route[0]]
        for w in new_route[1:]:
            if np.any(np.abs(w - route[-1]) > 1e-9):
                route.append(w)
        return route

    def _avoid_reason(self, v: int) -> str:
        if not self.has_target[v]:
            return f"status ({STATUS_NAMES[self.status.item(v)]}, holding)"
        if self.avoid_layer[v] >= 0:
            return "status (already on an avoidance layer)"
        return "separation (no avoidance layer clears)"
