"""What the ATC may clear now: each vehicle's legal actions (its mask) and the check of an
action against them.

The paper's table I gives the actions by status: a vehicle on a port may stay, take off or taxi
to a free port; a hovering one may stay or go to a free port (a landing) or hover spot; one in
transit may continue or avoid a predicted conflict; one away continues; one out of service
stays. On top of the paper, the ATC's energy check (``atc.energy_check``) clears only flights the
battery can finish with ``atc.energy_reserve_pct`` to spare (:mod:`~marl_vertiport.sim.energy`),
and lets a hovering vehicle hold only while a landing can still be cleared at its next turn; the
separation check (``atc.separation_check``, rules v1, :mod:`~marl_vertiport.sim.clearance`)
clears only flights whose protected volume clears every other vehicle's reservation, and an
avoidance climb only onto a layer that clears. Staying (on the ground, hovering) and continuing
(in flight) are always legal and safe, so no mask is ever empty.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, LEADING_ACTIONS, OUT_OF_SERVICE, STATUS_NAMES, TAXIING,
    format_actions,
)

#: Index of the first node action ("go to node 0"): the action layout of sim/schema.py.
_NODES = LEADING_ACTIONS
_IN_FLIGHT = (TAXIING, DEPARTING, ARRIVING)


class IllegalActionError(ValueError):
    """An action that is out of range, of the wrong type, or masked out."""


class Legality:
    """Masks and the action check of :class:`~marl_vertiport.sim.core.VertiportSim` (a part of
    it: the state it reads is the simulator's)."""

    def action_mask(self, v: int) -> np.ndarray:
        """Legal actions of vehicle ``v`` now, int8 of shape ``(A,)``, 1 = legal; never empty."""
        cached = self._mask_cache.get(v)
        if cached is not None:
            return cached
        if self.sep_check and self._memo_gen != self._memo.gen:
            self._check_memo()
        s = self.status.item(v)
        mask = self._fixed_masks[s]
        if mask is None and s in _IN_FLIGHT:  # rules v1: avoid only where a layer clears
            mask = self._flight_masks[self._avoid_layer(v) is not None]
        elif mask is None:  # on the ground or hovering: the free nodes it may go to
            acts = self.actions
            mask = np.zeros(acts.n, dtype=np.int8)
            mask[acts.stay] = 1
            free = self.node_occupant == -1
            if s == HOVERING:
                mask[_NODES:_NODES + self.layout.n_nodes] = free
            else:
                mask[acts.takeoff] = 1
                mask[_NODES:_NODES + self.layout.n_ports] = free[: self.layout.n_ports]
            atc = self.cfg.atc
            if atc.energy_check:  # clear only flights the battery can finish, with the reserve
                node = self.node.item(v)
                budget = self.battery.item(v) - atc.energy_reserve_pct
                hop = self.energy.hop_pct[node]
                mask[_NODES:_NODES + self.layout.n_nodes] &= hop < budget
                if s != HOVERING:
                    mask[acts.takeoff] = self.energy.trip_pct[node, self.dest.item(v)] < budget
            if self.sep_check:  # clear only flights whose volume clears every reservation
                self._apply_separation_check(v, mask, s != HOVERING)
            if atc.energy_check and s == HOVERING:
                # Hold only while a landing (one both checks clear) can still be cleared at the
                # next turn.
                ports = np.flatnonzero(mask[_NODES:_NODES + self.layout.n_ports])
                if ports.size and budget - self._hold_pct <= hop[ports].min():
                    mask[acts.stay] = 0
                    mask[_NODES + self.layout.n_ports:_NODES + self.layout.n_nodes] = 0
            mask.setflags(write=False)
        self._mask_cache[v] = mask
        return mask

    def flight_energy_pct(self, v: int, action: int) -> float:
        """Battery (percent, no gusts) that ``action`` (a take-off or a move to a node) of vehicle
        ``v``, on the ground or hovering at a node, needs to be finished; 0 for other actions."""
        node = self.node.item(v)
        if node < 0:
            return 0.0
        if action == self.actions.takeoff and self._is_port[node]:
            return float(self.energy.trip_pct[node, self.dest.item(v)])
        if _NODES <= action < _NODES + self.layout.n_nodes:
            return float(self.energy.hop_pct[node, action - _NODES])
        return 0.0

    def _in_flight_masks(self) -> tuple[np.ndarray, np.ndarray]:
        """Rules v1: the two read-only masks of a vehicle in flight, ``continue`` alone and
        ``continue`` or ``avoid`` (index: whether an avoidance layer clears)."""
        acts = self.actions
        masks = []
        for avoid in (False, True):
            mask = np.zeros(acts.n, dtype=np.int8)
            mask[acts.continue_] = 1
            mask[acts.avoid] = avoid
            mask.setflags(write=False)
            masks.append(mask)
        return masks[0], masks[1]

    def _status_masks(self) -> tuple[np.ndarray | None, ...]:
        """By status code, the read-only mask of a status whose legal actions do not depend on
        the occupancy of the nodes, or ``None``."""
        acts = self.actions
        legal = {TAXIING: (acts.continue_, acts.avoid), DEPARTING: (acts.continue_, acts.avoid),
                 ARRIVING: (acts.continue_, acts.avoid), AWAY: (acts.continue_,),
                 OUT_OF_SERVICE: (acts.stay,)}
        if self.cfg.atc.separation_check:  # in flight, avoid depends on the airspace
            for status in _IN_FLIGHT:
                del legal[status]
        masks: list[np.ndarray | None] = []
        for status in range(len(STATUS_NAMES)):
            if status not in legal:
                masks.append(None)
                continue
            mask = np.zeros(acts.n, dtype=np.int8)
            mask[list(legal[status])] = 1
            mask.setflags(write=False)
            masks.append(mask)
        return tuple(masks)

    def single_legal_action(self, v: int) -> int | None:
        """The one legal action of vehicle ``v`` now, or ``None`` when it has several."""
        only = self._fixed_single[self.status.item(v)]
        if only is not None:
            return only if only >= 0 else None
        legal = np.flatnonzero(self.action_mask(v))
        return int(legal[0]) if legal.size == 1 else None

    def check_action(self, v: int, action: Any, mask: np.ndarray | None = None) -> int:
        """Return ``action`` as an int if it is legal for vehicle ``v``, else raise; ``mask``
        replaces the vehicle's own mask as the legal set (the Parallel env's no-op of an agent
        whose turn it is not)."""
        if mask is None:
            mask = self.action_mask(v)
        if (type(action) is int or isinstance(action, np.integer)) and 0 <= action < len(mask) \
                and mask[action]:
            return int(action)
        names = self.actions.names(self.layout)
        legal = format_actions(np.flatnonzero(mask), names)
        if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
            if isinstance(action, np.ndarray) and action.shape == () and np.issubdtype(action.dtype, np.integer):
                action = int(action)
            else:
                raise IllegalActionError(
                    f"evtol_{v}: action {action!r} has type {type(action).__name__}, expected an "
                    f"integer in [0, {self.actions.n - 1}]; legal actions now: {legal}")
        a = int(action)
        if a < 0 or a >= self.actions.n:
            raise IllegalActionError(
                f"evtol_{v}: action {a} is out of range [0, {self.actions.n - 1}]; legal actions "
                f"now: {legal}")
        if not mask[a]:
            raise IllegalActionError(
                f"evtol_{v}: action {a} ({names[a]}) is masked out in status "
                f"{STATUS_NAMES[self.status[v]]}; legal actions now: {legal}")
        return a
