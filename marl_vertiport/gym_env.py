"""The fully centralised ATC as a single Gymnasium agent: ``"marl_vertiport/Vertiport-v1"``
(:class:`VertiportEnv`; ``"marl_vertiport/Vertiport-v0"``, :class:`VertiportEnvV0`, keeps the
rules of version 0 bit for bit).

Description:
    The same simulator as :mod:`marl_vertiport.vertiport_v1` (``-v0``: ``vertiport_v0``). At every step the agent acts
    for the eVTOL whose turn it is; the observation is that eVTOL's observation in the AEC env
    (same graphs, same ``action_mask``), and the reward is that eVTOL's reward.

Action Space:
    ``Discrete(4 + P)``, as in the AEC env. ``action_space.sample()`` without a mask draws
    uniformly among the legal actions of the eVTOL whose turn it is; an illegal action passed
    to ``step`` raises ``ValueError``.

Observation Space:
    ``Dict(observation=Dict(...), action_mask=Box(int8))``, as in the AEC env.

Rewards:
    The paper's weighted reward of the acting eVTOL.

Starting State:
    Vehicles on random ports (then hover spots) with full batteries and first flight plans.

Episode End:
    ``truncated`` after ``schedule.episode_steps`` (1440); ``terminated`` is always False.
    The last step's ``info["episode"]`` holds the episode metrics.

Arguments:
    ``config``, ``render_mode`` and keyword overrides, as in the AEC env.

Version History:
    * v1: the separation check and airspace procedures of ``vertiport_v1`` and its calibrated
      cruise drain (``battery.cruise_drain_scale`` 0.25) (2026-11-26); the same env with a flat
      ``Box`` observation as ``marl_vertiport/VertiportFlat-v1`` (2026-11-28). CHANGELOG.md,
      "Rules versions", dates every change.
    * v0: initial release (2026-11-22); ``marl_vertiport/Vertiport-v0`` keeps it bit for bit.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from marl_vertiport.config import LATEST_RULES, EnvConfig
from marl_vertiport.render import render_frame
from marl_vertiport.spaces import LegalDiscrete
from marl_vertiport.world import attach_world


class VertiportEnv(gym.Env):
    """Single-agent (fully centralised) vertiport env; see the module docstring."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 8}
    #: The rules version (marl_vertiport/config/rules.py).
    RULES = LATEST_RULES

    def __init__(self, config: str | EnvConfig | dict | None = None,
                 render_mode: str | None = None, **overrides: Any) -> None:
        attach_world(self, config, render_mode, overrides)
        self._started = False
        self.observation_space = self._builder.observation_space
        # sample() draws among the legal actions of the acting eVTOL (see LegalDiscrete).
        self.action_space = LegalDiscrete(self.sim.actions.n, self.action_masks)
        self.state_space = self._builder.state_space

    def _info(self, step_info: dict[str, Any]) -> dict[str, Any]:
        return dict(step_info, agent=f"evtol_{self.sim.acting}")

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.sim.reset(self.np_random)
        self._started = True
        return self._builder.observe(self.sim.acting), self._info({})

    def step(self, action: Any):
        if not self._started:
            raise RuntimeError("reset() must be called before step()")
        if self.sim.truncated:
            raise RuntimeError(f"the episode ended (truncated after {self.sim.step_count} steps); "
                               "call reset() to start another")
        reward, info = self.sim.step(action)
        truncated = self.sim.truncated
        info = self._info(info)
        if truncated:
            info["episode"] = self.sim.episode_metrics()
        return self._builder.observe(self.sim.acting), reward, False, truncated, info

    def state(self) -> dict:
        """Global noise-free graph, as the AEC env's ``state()`` (after ``reset()``)."""
        if not self._started:
            raise RuntimeError("reset() must be called before state()")
        return self._builder.state()

    def action_masks(self) -> np.ndarray:
        """Legal actions of the eVTOL whose turn it is (int8)."""
        return self.sim.action_mask(self.sim.acting).copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return render_frame(self.sim)
        return None

    def close(self) -> None:
        self.sim.close()


class VertiportEnvV0(VertiportEnv):
    """``"marl_vertiport/Vertiport-v0"``: :class:`VertiportEnv` under the rules of version 0."""

    RULES = 0
