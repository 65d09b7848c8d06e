"""The vertiport's graph observation as flat vectors, for libraries whose default models read
one array per key.

:class:`FlatObservation` wraps the AEC env (PettingZoo only, no RL library) and turns every
observation ``{"action_mask": int8 (A,), "observation": {evtol_nodes, port_nodes, self}}``
into::

    {"action_mask": int8 (A,),            # unchanged: 1 = legal
     "observations": float32 (D,),        # evtol_nodes, port_nodes, self, each row-major
     "state": float32 (S,)}               # only with with_state=True: env.state(), flattened

``"state"`` is the global, noise-free graph of ``env.state()`` (the same for every agent):
it lets a library that sees only observations (RLlib's ``PettingZooEnv``) give it to a
centralised critic. The actor must not read it: it is not what a deployed eVTOL observes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv
from pettingzoo.utils.wrappers import BaseWrapper

__all__ = ["FlatObservation", "flatten"]


def flatten(arrays: dict[str, np.ndarray], keys: tuple[str, ...]) -> np.ndarray:
    """The arrays of ``keys``, each raveled, end to end as one float32 vector."""
    return np.concatenate([np.asarray(arrays[k], dtype=np.float32).ravel() for k in keys])


def _size(space: spaces.Dict) -> int:
    return sum(int(np.prod(s.shape)) for s in space.spaces.values())


class FlatObservation(BaseWrapper):
    """An AEC wrapper whose observations are ``{"action_mask", "observations"[, "state"]}``.

    Args:
        env: the vertiport AEC env (``vertiport_v1.env(...)`` or ``raw_env(...)``).
        with_state: also put the flattened ``env.state()`` in every observation.
    """

    def __init__(self, env: AECEnv, with_state: bool = False) -> None:
        super().__init__(env)
        inner = env.observation_space(env.possible_agents[0])
        graph: spaces.Dict = inner["observation"]
        self.observation_keys = tuple(graph.spaces)
        self.with_state = with_state
        flat = {
            "action_mask": inner["action_mask"],
            "observations": spaces.Box(-np.inf, np.inf, (_size(graph),), np.float32),
        }
        if with_state:
            state_space: spaces.Dict = env.unwrapped.state_space
            self.state_keys = tuple(state_space.spaces)
            flat["state"] = spaces.Box(-np.inf, np.inf, (_size(state_space),), np.float32)
        self._space = spaces.Dict(flat)
        self.observation_spaces = dict.fromkeys(env.possible_agents, self._space)

    def observation_space(self, agent: str) -> spaces.Dict:
        return self._space

    def observe(self, agent: str) -> dict[str, Any]:
        obs = self.env.observe(agent)
        out = {"action_mask": obs["action_mask"],
               "observations": flatten(obs["observation"], self.observation_keys)}
        if self.with_state:
            out["state"] = flatten(self.env.state(), self.state_keys)
        return out
