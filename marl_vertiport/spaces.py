"""Observation, state and action spaces, and the translation from the simulator's arrays to
observations. Shared by the AEC env and the single-agent env so both see the same thing."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import (
    EVTOL_FEATURES, PORT_FEATURES, SELF_FEATURES, STATE_EXTRA_FEATURES, STATE_PORT_FEATURES,
    CLOCK_FEATURES,
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
    """Builds the spaces once and the per-agent observations of one simulator.

    Observation of vehicle ``v`` (a dict):

    - ``observation["port_nodes"]``: ``(P, 4)`` float32, :data:`PORT_FEATURES`.
    - ``observation["evtol_nodes"]``: ``(N, 13)`` float32, :data:`EVTOL_FEATURES`.
    - ``observation["self"]``: ``(11,)`` float32, :data:`SELF_FEATURES` of ``v``.
    - ``action_mask``: ``(A,)`` int8, 1 = legal.

    Both graphs are complete (every node is linked to every other), so no edge arrays are
    sent; :func:`marl_vertiport.graph.to_graph_batch` builds them for torch-geometric.
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

    def observe(self, v: int) -> dict:
        sim = self.sim
        return {
            "observation": {
                "port_nodes": sim.port_nodes(),
                "evtol_nodes": sim.evtol_nodes(v),
                "self": sim.self_features(v),
            },
            "action_mask": sim.action_mask(v).copy(),
        }

    def state(self) -> dict:
        return self.sim.state_arrays()
