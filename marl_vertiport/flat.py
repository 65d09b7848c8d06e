"""The observation as one flat ``Box`` (the graphs and the mask end to end), for code that reads
one array: Stable-Baselines3's ``MlpPolicy``, SuperSuit's observation wrappers, CleanRL-style
scripts.

Columns (:func:`flat_columns` names each one; ``N`` eVTOLs, ``P`` vertiport nodes, ``A = 4 + P``
actions)::

    [0, 13 N)                   evtol_nodes, row-major: evtol_nodes[i].<EVTOL_FEATURES>
    [13 N, 13 N + 4 P)          port_nodes,  row-major: port_nodes[k].<PORT_FEATURES>
    [13 N + 4 P, .. + 11)       self.<SELF_FEATURES>
    [.. + 11, .. + 11 + A)      action_mask[<action name>], 1.0 = legal

The units are the graph observation's (docs/environment.md). The ``Box`` has finite bounds,
per column, from the vertiport itself (:func:`flat_bounds`), so SuperSuit's ``normalize_obs_v0``
can scale it; a value outside them is clipped into them and counted (``clipped``; a test plays
busy days of every shipped config and finds none). The mask also stays where each library looks
for it: ``action_masks()`` (sb3-contrib's ``MaskablePPO``) and ``info["action_mask"]``.

* :class:`FlatObservation`: a Gymnasium wrapper of the single-agent env;
  ``gymnasium.make("marl_vertiport/VertiportFlat-v1")`` builds the two together.
* :class:`FlatParallel`: a PettingZoo Parallel wrapper of ``vertiport_v1.parallel_env()``
  (SuperSuit's vector envs and observation wrappers on the multi-agent env).
* :class:`FlatAEC`: a PettingZoo AEC wrapper of ``vertiport_v1.env()`` for libraries whose
  default models read one array per key (RLlib's ``PettingZooEnv``): every observation becomes
  ``{"action_mask": int8 (A,), "observations": float32 (D - A,)}`` (the layout above without
  the mask's columns, which stay under their own key), and with ``with_state=True`` also
  ``"state": float32 (S,)``, ``env.state()`` flattened, so that a library that sees only
  observations can give the global state to a centralised critic. The actor must not read
  ``"state"``: it is not what a deployed eVTOL observes.

This is the project's one flattener; before 0.2.0 the AEC wrapper was
``agents.interop.flat.FlatObservation``.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv
from pettingzoo.utils.wrappers import BaseParallelWrapper, BaseWrapper

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import (
    EVTOL_FEATURES, PORT_FEATURES, SELF_FEATURES, STATUS_NAMES, EARLY, DELAYED,
)

__all__ = ["FlatAEC", "FlatObservation", "FlatParallel", "flat_bounds", "flat_columns",
           "flatten_arrays", "flatten_observation", "make_flat_env"]

_GRAPH_KEYS = ("evtol_nodes", "port_nodes", "self")


def flat_columns(sim: VertiportSim) -> list[str]:
    """The name of every column of the flat observation of ``sim``'s vertiport, in order."""
    names = [f"evtol_nodes[{i}].{f}" for i in range(sim.n) for f in EVTOL_FEATURES]
    names += [f"port_nodes[{k}].{f}" for k in range(sim.layout.n_nodes) for f in PORT_FEATURES]
    names += [f"self.{f}" for f in SELF_FEATURES]
    names += [f"action_mask[{a}]" for a in sim.actions.names(sim.layout)]
    return names


def _feature_bounds(sim: VertiportSim) -> dict[str, tuple[float, float]]:
    """Bounds of each graph feature on ``sim``'s vertiport: the feature's range where it is a
    code or a fraction, else twice the farthest the day can take it (positions: the farthest
    destination or node plus ten standard deviations of position noise; altitudes: the highest
    avoidance layer; speeds: the cruise speed; minutes: the length of the day)."""
    cfg, lay = sim.cfg, sim.layout
    reach_m = float(max(np.abs(lay.destination_xy_m).max(initial=0.0),
                        np.abs(lay.node_xy_m).max(initial=0.0), lay.airspace_radius_m))
    unc = cfg.uncertainty
    reach_m = 2.0 * reach_m + abs(unc.position_noise_mean_m) + 10.0 * unc.position_noise_std_m
    fl = cfg.flight
    top_m = 2.0 * max((fl.transit_altitude_m, fl.departure_altitude_m, fl.arrival_altitude_m,
                       fl.hover_altitude_m, *fl.avoid_altitudes_m))
    speed = 2.0 * fl.cruise_speed_mps
    day_min = 2.0 * cfg.schedule.episode_steps * cfg.schedule.minutes_per_step
    return {
        "status": (0.0, float(len(STATUS_NAMES) - 1)), "battery_pct": (0.0, 100.0),
        "schedule_status": (float(EARLY), float(DELAYED)),
        "x_m": (-reach_m, reach_m), "y_m": (-reach_m, reach_m), "z_m": (0.0, top_m),
        "vx_mps": (-speed, speed), "vy_mps": (-speed, speed),
        "minutes_to_schedule": (-day_min, day_min), "delay_min": (0.0, day_min),
        "conflict": (0.0, 1.0), "node": (-1.0, float(lay.n_nodes - 1)), "is_self": (0.0, 1.0),
        "available": (0.0, 1.0), "type": (0.0, float(lay.node_type.max(initial=0))),
    }


def flat_bounds(sim: VertiportSim) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)``, float32 of shape ``(D,)``: each column's bounds (:func:`_feature_bounds`;
    the mask's columns in [0, 1])."""
    b = _feature_bounds(sim)
    cols = ([b[f] for f in EVTOL_FEATURES] * sim.n + [b[f] for f in PORT_FEATURES] * sim.layout.n_nodes
            + [b[f] for f in SELF_FEATURES] + [(0.0, 1.0)] * sim.actions.n)
    bounds = np.asarray(cols, dtype=np.float32)
    return bounds[:, 0].copy(), bounds[:, 1].copy()


def flatten_arrays(arrays: dict[str, np.ndarray], keys: tuple[str, ...]) -> np.ndarray:
    """The arrays of ``keys``, each raveled (row-major), end to end as one float32 vector."""
    return np.concatenate([np.asarray(arrays[k], dtype=np.float32).ravel() for k in keys])


def flatten_observation(obs: dict[str, Any]) -> np.ndarray:
    """A graph observation (``{"observation": {...}, "action_mask"}``) as the flat float32
    vector of the module's column layout (not clipped)."""
    return np.concatenate([flatten_arrays(obs["observation"], _GRAPH_KEYS),
                           np.asarray(obs["action_mask"], dtype=np.float32)])


class _Flattener:
    """The flat space of one vertiport, and observations flattened and clipped into it."""

    def __init__(self, sim: VertiportSim) -> None:
        self.low, self.high = flat_bounds(sim)
        self.space = spaces.Box(self.low, self.high, dtype=np.float32)
        self.columns = flat_columns(sim)
        #: Values clipped into the bounds since this wrapper was built.
        self.clipped = 0

    def __call__(self, obs: dict[str, Any]) -> np.ndarray:
        flat = flatten_observation(obs)
        out = np.clip(flat, self.low, self.high)
        self.clipped += int(np.count_nonzero(out != flat))
        return out


def _vertiport_sim(env: Any) -> VertiportSim:
    sim = getattr(env.unwrapped, "sim", None)
    if not isinstance(sim, VertiportSim):
        raise TypeError(f"expected a vertiport env (marl_vertiport), got {type(env.unwrapped).__name__}")
    return sim


class FlatObservation(gymnasium.ObservationWrapper):
    """The single-agent env with the flat ``Box`` observation (the module's column layout).

    ``action_masks()`` gives the acting eVTOL's legal actions (int8 ``(A,)``) and every step's
    and reset's ``info["action_mask"]`` the same; ``columns`` names the observation's columns.
    """

    def __init__(self, env: gymnasium.Env) -> None:
        super().__init__(env)
        self._flat = _Flattener(_vertiport_sim(env))
        self.observation_space = self._flat.space
        self.columns = self._flat.columns

    @property
    def clipped(self) -> int:
        """Values clipped into the bounds so far (none expected; see the module docstring)."""
        return self._flat.clipped

    def observation(self, observation: dict[str, Any]) -> np.ndarray:
        self._mask = observation["action_mask"]
        return self._flat(observation)

    def reset(self, **kwargs: Any):
        obs, info = super().reset(**kwargs)
        return obs, dict(info, action_mask=self._mask.copy())

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, dict(info, action_mask=self._mask.copy())

    def action_masks(self) -> np.ndarray:
        """Legal actions of the eVTOL whose turn it is (int8 ``(A,)``)."""
        return self.env.unwrapped.action_masks()


def make_flat_env(**kwargs: Any) -> FlatObservation:
    """The entry point of ``marl_vertiport/VertiportFlat-v1``: the single-agent env (``config``,
    ``render_mode``, overrides) in :class:`FlatObservation`."""
    from marl_vertiport.gym_env import VertiportEnv

    return FlatObservation(VertiportEnv(**kwargs))


class FlatParallel(BaseParallelWrapper):
    """The Parallel env with the flat ``Box`` observation for every agent (the module's column
    layout, each agent's own mask in its last ``A`` columns and in ``infos[agent]["action_mask"]``).
    """

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self._flat = _Flattener(_vertiport_sim(env))
        self.columns = self._flat.columns
        self.observation_spaces = dict.fromkeys(env.possible_agents, self._flat.space)

    @property
    def clipped(self) -> int:
        """Values clipped into the bounds so far (none expected; see the module docstring)."""
        return self._flat.clipped

    def observation_space(self, agent: str) -> spaces.Box:
        return self._flat.space

    def _convert(self, observations: dict, infos: dict) -> tuple[dict, dict]:
        flat = {a: self._flat(o) for a, o in observations.items()}
        infos = {a: dict(infos.get(a, {}), action_mask=o["action_mask"].copy())
                 for a, o in observations.items()}
        return flat, infos

    def reset(self, seed: int | None = None, options: dict | None = None):
        return self._convert(*self.env.reset(seed=seed, options=options))

    def step(self, actions: dict[str, Any]):
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        flat, infos = self._convert(observations, infos)
        return flat, rewards, terminations, truncations, infos

    def state(self) -> dict:
        return self.env.state()


class FlatAEC(BaseWrapper):
    """The AEC env with observations ``{"action_mask", "observations"[, "state"]}`` (the module
    docstring): the graph columns of the flat layout, clipped into their bounds, and the mask
    apart.

    Args:
        env: the vertiport AEC env (``vertiport_v1.env(...)`` or ``raw_env(...)``).
        with_state: also put the flattened ``env.state()`` in every observation.
    """

    def __init__(self, env: AECEnv, with_state: bool = False) -> None:
        super().__init__(env)
        self._flat = _Flattener(_vertiport_sim(env))
        mask_space = env.observation_space(env.possible_agents[0])["action_mask"]
        self._graph_columns = len(self._flat.columns) - int(mask_space.shape[0])
        #: The names of the ``"observations"`` columns.
        self.columns = self._flat.columns[:self._graph_columns]
        self.with_state = with_state
        flat = {"action_mask": mask_space,
                "observations": spaces.Box(self._flat.low[:self._graph_columns],
                                           self._flat.high[:self._graph_columns],
                                           dtype=np.float32)}
        if with_state:
            state_space: spaces.Dict = env.unwrapped.state_space
            self.state_keys = tuple(state_space.spaces)
            size = sum(int(np.prod(s.shape)) for s in state_space.spaces.values())
            flat["state"] = spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self._space = spaces.Dict(flat)
        self.observation_spaces = dict.fromkeys(env.possible_agents, self._space)

    @property
    def clipped(self) -> int:
        """Values clipped into the bounds so far (none expected; see the module docstring)."""
        return self._flat.clipped

    def observation_space(self, agent: str) -> spaces.Dict:
        return self._space

    def observe(self, agent: str) -> dict[str, Any]:
        obs = self.env.observe(agent)
        out = {"action_mask": obs["action_mask"],
               "observations": self._flat(obs)[:self._graph_columns]}
        if self.with_state:
            out["state"] = flatten_arrays(self.env.state(), self.state_keys)
        return out
