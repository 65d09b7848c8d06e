"""Observation, state and action spaces, and the translation from the simulator's arrays to
observations. Shared by the AEC env and the single-agent env so both see the same thing."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from gymnasium import spaces

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import (
    CLOCK_FEATURES, EVTOL_FEATURES, PORT_FEATURES, SELF_FEATURES, STATE_EXTRA_FEATURES,
    STATE_PORT_FEATURES, _IS_SELF,
)


class LegalDiscrete(spaces.Discrete):
    """``Discrete(n)`` whose :meth:`sample` without a mask draws among the actions legal now.

    Used by the single-agent env, where the legal set belongs to the eVTOL whose turn it is:
    ``env.action_space.sample()`` is always a valid action. ``contains`` is unchanged (every
    index is in the space; legality is the env's check). Copies and pickles are plain
    ``Discrete`` spaces, so vector wrappers never drag the simulator along.
    """

    def __init__(self, n: int, legal_mask_fn) -> None:
        super().__init__(n)
        self._legal_mask_fn = legal_mask_fn

    def sample(self, mask=None, probability=None):
        if mask is None and probability is None:
            mask = self._legal_mask_fn()
        return super().sample(mask=mask, probability=probability)

    def __deepcopy__(self, memo) -> spaces.Discrete:
        plain = spaces.Discrete(self.n)
        plain.np_random.bit_generator.state = self.np_random.bit_generator.state
        return plain

    def __reduce__(self):
        return (spaces.Discrete, (int(self.n),))


def _box(shape: tuple[int, ...], low: float = -np.inf, high: float = np.inf,
         dtype: type = np.float32) -> spaces.Box:
    return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)


class ObservationBuilder:
    """Builds the spaces once, and the observations of one simulator: the one path from the
    simulator's graph features (:mod:`marl_vertiport.sim.features`) to what a policy reads,
    for the AEC env, the single-agent env and the training vector env alike.

    Observation of vehicle ``v`` (a dict):

    - ``observation["port_nodes"]``: ``(P, 4)`` float32, :data:`PORT_FEATURES`.
    - ``observation["evtol_nodes"]``: ``(N, 13)`` float32, :data:`EVTOL_FEATURES`, ``is_self``
      marking ``v``.
    - ``observation["self"]``: ``(11,)`` float32, :data:`SELF_FEATURES` of ``v``.
    - ``action_mask``: ``(A,)`` int8, 1 = legal.

    Both graphs are complete (every node is linked to every other), so no edge arrays are
    sent; :func:`marl_vertiport.graph.to_graph_batch` builds them for torch-geometric.
    :meth:`observe_into` and :meth:`state_into` write the graphs of several vehicles at once
    into arrays with a leading row dimension (the batch the training vector env reads).
    """

    def __init__(self, sim: VertiportSim) -> None:
        self.sim = sim
        n, p, a = sim.n, sim.layout.n_nodes, sim.actions.n
        graph = spaces.Dict({
            "port_nodes": _box((p, len(PORT_FEATURES))),
            "evtol_nodes": _box((n, len(EVTOL_FEATURES))),
            "self": _box((len(SELF_FEATURES),)),
        })
        self.observation_space = spaces.Dict({
            "observation": graph,
            "action_mask": spaces.Box(0, 1, shape=(a,), dtype=np.int8),
        })
        self.state_space = spaces.Dict({
            "port_nodes": _box((p, len(STATE_PORT_FEATURES))),
            "evtol_nodes": _box((n, len(EVTOL_FEATURES) + len(STATE_EXTRA_FEATURES))),
            "clock": _box((len(CLOCK_FEATURES),)),
        })
        self.action_space = spaces.Discrete(a)

    def observe(self, v: int, action_mask: np.ndarray | None = None) -> dict:
        """The observation of vehicle ``v`` (new arrays): :meth:`observe_into` for one row,
        written out for the env's hot path (a test holds the two equal). ``action_mask``
        (``(A,)`` int8) replaces the vehicle's own mask (the Parallel env's no-op mask of an
        agent whose turn it is not)."""
        sim = self.sim
        base = sim.evtol_features()
        evtols = base.copy()
        evtols[v, _IS_SELF] = 1.0
        return {
            "observation": {"port_nodes": sim.port_features().copy(), "evtol_nodes": evtols,
                            "self": base[v, : len(SELF_FEATURES)].copy()},
            "action_mask": (sim.action_mask(v) if action_mask is None else action_mask).copy(),
        }

    def observe_into(self, observers: Sequence[int], port_nodes: np.ndarray,
                     evtol_nodes: np.ndarray, own: np.ndarray) -> None:
        """Write the observation graphs of several vehicles, one row each.

        Args:
            observers: per row, the vehicle that observes; ``-1`` for a row of no vehicle (a
                padded row: the graphs without ``is_self``, its own features left as they are).
            port_nodes: ``(R, P', 4)`` with ``P' >= P``: columns ``:P`` of every row written.
            evtol_nodes: ``(R, N', 13)`` with ``N' >= N``: columns ``:N`` of every row written.
            own: ``(R, 11)``: the rows of vehicles written.
        """
        sim = self.sim
        base = sim.evtol_features()
        port_nodes[:, : sim.layout.n_nodes] = sim.port_features()
        evtol_nodes[:, : sim.n] = base
        rows, vehicles = _observer_rows(observers)
        if rows.size:
            evtol_nodes[rows, vehicles, _IS_SELF] = 1.0
            own[rows] = base[vehicles, : len(SELF_FEATURES)]

    def state(self) -> dict:
        """The global state (``state()`` of both envs): ``is_self`` marks the acting vehicle."""
        return self.sim.state_arrays()

    def state_into(self, observers: Sequence[int], port_nodes: np.ndarray,
                   evtol_nodes: np.ndarray, clock: np.ndarray) -> None:
        """Write the global state once per row, ``is_self`` marking the row's vehicle (``-1``:
        none), as a centralised critic reads it for that vehicle; the shapes as in
        :meth:`observe_into`, with the state's columns (``(R, P', 5)``, ``(R, N', 17)``,
        ``(R, 3)``)."""
        sim = self.sim
        state = sim.state_arrays()
        port_nodes[:, : sim.layout.n_nodes] = state["port_nodes"]
        evtol_nodes[:, : sim.n] = state["evtol_nodes"]
        evtol_nodes[:, : sim.n, _IS_SELF] = 0.0
        rows, vehicles = _observer_rows(observers)
        if rows.size:
            evtol_nodes[rows, vehicles, _IS_SELF] = 1.0
        clock[:] = state["clock"]


def _observer_rows(observers: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, vehicles)`` of the rows that have an observing vehicle."""
    vehicles = np.asarray(observers, dtype=np.intp)
    rows = np.flatnonzero(vehicles >= 0)
    return rows, vehicles[rows]
