"""The controller interface and a named view of observations (the episode loop that drives a
controller is :mod:`agents.controllers.episode`).

A controller (policy) is any object with ``act(observation) -> int`` that returns a legal action
for the eVTOL whose observation it gets (the observation of the AEC env, which is also the
single-agent env's observation), and optionally ``reset(seed)`` called at the start of every
episode. One object acts for every eVTOL in turn, as the centralised ATC does.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, EVTOL_FEATURES, HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE,
    PORT_FEATURES, TAXIING, ActionLayout,
)
from marl_vertiport.sim.layout import CHARGING_PORT, HOVER_SPOT, NORMAL_PORT

__all__ = [
    "ARRIVING", "AWAY", "DEPARTING", "HOVERING", "ON_CHARGER", "ON_PORT", "OUT_OF_SERVICE",
    "TAXIING", "CHARGING_PORT", "HOVER_SPOT", "NORMAL_PORT", "Controller", "Observation",
    "Policy",
]

_COL = {name: i for i, name in enumerate(EVTOL_FEATURES)}
_PORT_COL = {name: i for i, name in enumerate(PORT_FEATURES)}


@runtime_checkable
class Policy(Protocol):
    """What the evaluation, the renderer and the envs' loops need from a controller."""

    def act(self, observation: dict) -> int: ...


class Controller:
    """Convenience base class: ``reset`` does nothing, ``__call__`` is ``act``."""

    name = "controller"
    #: Whether ``act`` is a pure function of its observation: no state it changes, no random
    #: draws. A planner may then skip asking it where only one action is legal.
    pure_act = False

    def reset(self, seed: int | None = None) -> None:
        """Start of an episode; ``seed`` seeds any randomness of the controller."""

    def act(self, observation: dict) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def __call__(self, observation: dict) -> int:
        return self.act(observation)


class Observation:
    """Named access to one AEC observation (see docs/observations.md, section 5, and
    docs/controllers.md).

    Reading the graphs: ``fleet(name)`` is a column of the eVTOL graph, one value per vehicle
    ``(N,)``; ``mine(name)`` is that column's value for the acting eVTOL; ``ports(name)`` is a
    column of the vertiport graph ``(P,)``; ``status`` and ``me`` (the acting eVTOL's row) are
    shortcuts. Column names: ``EVTOL_FEATURES`` and ``PORT_FEATURES`` of
    ``marl_vertiport.sim.schema``.

    Actions (``[stay, take off, node 0 .. node P-1, continue, avoid]``): ``stay``, ``takeoff``,
    ``go_to(node)``, ``continue_``, ``avoid``; ``mask`` ``(4 + P,)`` says which are legal now,
    ``legal()`` lists them, ``free_nodes(type)`` and ``reachable_nodes(type)`` the nodes of a type
    that are free, or that the acting eVTOL may move to now.

    Example::

        obs = Observation(observation)
        chargers = obs.reachable_nodes(CHARGING_PORT)
        if obs.status == HOVERING and chargers.size:
            return obs.go_to(int(chargers[0]))
        if obs.mask[obs.takeoff] and obs.mine("minutes_to_schedule") <= 0:
            return obs.takeoff
        return obs.stay if obs.mask[obs.stay] else int(obs.legal()[0])
    """

    # A plain class with slots, not a dataclass with cached properties: a controller builds one
    # per decision, and in Python 3.11 every first read of a cached property takes a lock.
    __slots__ = ("raw", "_evtol_rows", "_port_rows", "_mask", "_me", "_actions")

    def __init__(self, raw: dict) -> None:
        #: The observation as the env gave it.
        self.raw = raw
        self._evtol_rows: np.ndarray | None = None
        self._port_rows: np.ndarray | None = None
        self._mask: np.ndarray | None = None
        self._me: int | None = None
        self._actions: ActionLayout | None = None

    def __repr__(self) -> str:
        return f"Observation(raw={self.raw!r})"

    @property
    def _evtols(self) -> np.ndarray:
        if self._evtol_rows is None:
            self._evtol_rows = np.asarray(self.raw["observation"]["evtol_nodes"])
        return self._evtol_rows

    @property
    def _ports(self) -> np.ndarray:
        if self._port_rows is None:
            self._port_rows = np.asarray(self.raw["observation"]["port_nodes"])
        return self._port_rows

    @property
    def mask(self) -> np.ndarray:
        """The action mask, int8 ``(4 + P,)``; 1 = legal now."""
        if self._mask is None:
            self._mask = np.asarray(self.raw["action_mask"])
        return self._mask

    @property
    def me(self) -> int:
        """Row of the acting eVTOL in the eVTOL graph (its ``is_self`` column)."""
        if self._me is None:
            self._me = int(np.argmax(self._evtols[:, _COL["is_self"]]))
        return self._me

    def fleet(self, name: str) -> np.ndarray:
        """Column ``name`` of the eVTOL graph, ``(N,)``, e.g. ``fleet("battery_pct")``."""
        return self._evtols[:, _COL[name]]

    def mine(self, name: str) -> float:
        """Column ``name`` of the acting eVTOL, e.g. ``mine("minutes_to_schedule")``."""
        return float(self._evtols[self.me, _COL[name]])

    def ports(self, name: str) -> np.ndarray:
        """Column ``name`` of the vertiport graph, ``(P,)``: ``available``, ``type``, ``x_m``,
        ``y_m``."""
        return self._ports[:, _PORT_COL[name]]

    @property
    def status(self) -> int:
        """The acting eVTOL's status code (``ON_PORT`` .. ``OUT_OF_SERVICE``)."""
        return int(self.mine("status"))

    @property
    def n_nodes(self) -> int:
        """Number of vertiport nodes ``P`` (ports, charging ports, hover spots)."""
        return self._ports.shape[0]

    # Action indices (paper's table I order; docs/environment.md, section 4).
    stay = ActionLayout.stay
    takeoff = ActionLayout.takeoff

    @property
    def actions(self) -> ActionLayout:
        """The action layout of this observation's vertiport."""
        if self._actions is None:
            self._actions = ActionLayout(self.n_nodes)
        return self._actions

    def go_to(self, node: int) -> int:
        """Action that moves to / lands on vertiport node ``node``."""
        return self.actions.node_action(int(node))

    @property
    def continue_(self) -> int:
        """Action that keeps a vehicle in transit on its way."""
        return self.actions.continue_

    @property
    def avoid(self) -> int:
        """Action that makes a vehicle in transit climb to an avoidance altitude."""
        return self.actions.avoid

    def free_nodes(self, node_type: int) -> np.ndarray:
        """Indices of the free nodes of one type (NORMAL_PORT, CHARGING_PORT, HOVER_SPOT)."""
        return np.flatnonzero((self.ports("available") == 1) & (self.ports("type") == node_type))

    def reachable_nodes(self, node_type: int) -> np.ndarray:
        """Indices of the nodes of one type that the acting eVTOL may move to now: free, and
        within its battery when the env checks energy (``atc.energy_check``)."""
        first = self.actions.node_action(0)
        moves = self.mask[first:first + self.n_nodes] == 1
        return np.flatnonzero(moves & (self.ports("type") == node_type))

    def node_type(self, node: int) -> int:
        """Type of vertiport node ``node`` (``NORMAL_PORT``, ``CHARGING_PORT``, ``HOVER_SPOT``)."""
        return int(self.ports("type")[int(node)])

    def legal(self) -> np.ndarray:
        """Indices of the legal actions."""
        return np.flatnonzero(self.mask)
