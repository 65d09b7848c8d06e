"""The PettingZoo AEC env's implementation, shared by its versions (:mod:`marl_vertiport.vertiport_v1`,
the latest, and :mod:`marl_vertiport.vertiport_v0`): a version is a class of this module's with
its rules (:mod:`marl_vertiport.config.rules`) and its name. The versions' modules document the
env as PettingZoo's do.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from pettingzoo import AECEnv
from pettingzoo.utils import wrappers
from pettingzoo.utils.env_logger import EnvLogger
from pettingzoo.utils.wrappers.order_enforcing import (
    AECOrderEnforcingIterable, AECOrderEnforcingIterator,
)

from marl_vertiport.config import LATEST_RULES, EnvConfig
from marl_vertiport.render import render_frame
from marl_vertiport.world import agent_names, attach_world

__all__ = ["OrderEnforcing", "VertiportAEC", "reset_agent_dicts"]


class OrderEnforcing(wrappers.OrderEnforcingWrapper):
    """PettingZoo's order-enforcing wrapper with the calls of every step answered by the raw env
    in one hop.

    The inherited ``last()``, ``step()`` and agent iterator read the agent, its reward, flags,
    info and the agent list through the wrapper's ``__getattr__`` (two hops per attribute,
    about 12 a step); these read the raw env's attributes directly and return the same values,
    with the same errors and warnings before ``reset`` and after the episode."""

    def last(self, observe: bool = True) -> tuple:
        if not self._has_reset:
            raise AttributeError("agent_selection cannot be accessed before reset")
        return self.env.last(observe)

    def step(self, action: Any) -> None:
        if not self._has_reset:
            EnvLogger.error_step_before_reset()
        self._has_updated = True
        if not self.env.agents:
            EnvLogger.warn_step_after_terminated_truncated()
        else:
            self.env.step(action)

    def agent_iter(self, max_iter: int = 2**63) -> AECOrderEnforcingIterable:
        if not self._has_reset:
            EnvLogger.error_agent_iter_before_reset()
        return _AgentIterable(self, max_iter)

    def __str__(self) -> str:
        return str(self.env)


class _AgentIterable(AECOrderEnforcingIterable):
    def __iter__(self) -> AECOrderEnforcingIterator:
        return _AgentIterator(self.env, self.max_iter)


class _AgentIterator(AECOrderEnforcingIterator):
    """PettingZoo's order-enforcing agent iterator reading the raw env's agents directly."""

    def __next__(self) -> str:
        wrapper = self.env
        raw = wrapper.env
        if not raw.agents or self.iters_til_term <= 0:
            raise StopIteration
        self.iters_til_term -= 1
        assert wrapper._has_updated, "need to call step() or reset() in a loop over `agent_iter`"
        wrapper._has_updated = False
        return raw.agent_selection


def reset_agent_dicts(aec: AECEnv) -> None:
    """An AEC env's per-agent bookkeeping at the start of an episode: every possible agent
    present, rewards 0, no termination or truncation, empty infos."""
    aec.agents = aec.possible_agents[:]
    aec.rewards = dict.fromkeys(aec.agents, 0.0)
    aec._cumulative_rewards = dict.fromkeys(aec.agents, 0.0)
    aec.terminations = dict.fromkeys(aec.agents, False)
    aec.truncations = dict.fromkeys(aec.agents, False)
    aec.infos = {a: {} for a in aec.agents}


class VertiportAEC(AECEnv):
    """Unwrapped AEC env under the rules of version :attr:`RULES`; see the versions' modules."""

    #: The rules version (marl_vertiport/config/rules.py).
    RULES = LATEST_RULES
    metadata = {
        "render_modes": ["human", "rgb_array"],
        "name": f"vertiport_v{LATEST_RULES}",
        "is_parallelizable": False,
        "render_fps": 8,
    }

    def __init__(self, config: str | EnvConfig | dict | None = None,
                 render_mode: str | None = None, **overrides: Any) -> None:
        super().__init__()
        attach_world(self, config, render_mode, overrides)
        self.possible_agents, self.agent_name_mapping = agent_names(self.sim.n)
        self.observation_spaces = dict.fromkeys(self.possible_agents, self._builder.observation_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, self._builder.action_space)
        self.state_space = self._builder.state_space
        self._rng: np.random.Generator | None = None
        self.agents: list[str] = []

    def observation_space(self, agent: str):
        return self.observation_spaces[agent]

    def action_space(self, agent: str):
        return self.action_spaces[agent]

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        if seed is not None or self._rng is None:
            self._rng, _ = seeding.np_random(seed)
        self.sim.reset(self._rng)
        reset_agent_dicts(self)
        self.agent_selection = self.possible_agents[self.sim.acting]
        self._last_rewarded: str | None = None

    def observe(self, agent: str) -> dict:
        v = self.agent_name_mapping.get(agent)
        if v is None:
            raise KeyError(f"unknown agent {agent!r}; the agents are {', '.join(self.possible_agents)}")
        if self._rng is None:
            raise RuntimeError("reset() must be called before observe()")
        return self._builder.observe(v)

    def state(self) -> dict:
        if self._rng is None:
            raise RuntimeError("reset() must be called before state()")
        return self._builder.state()

    def step(self, action: Any) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        if self.agent_name_mapping[agent] != self.sim.acting:  # pragma: no cover - invariant
            raise RuntimeError(f"{agent} acts out of turn (turn of evtol_{self.sim.acting})")
        reward, info = self.sim.step(action)  # raises before any change on an illegal action
        if self._last_rewarded is not None:
            self.rewards[self._last_rewarded] = 0.0
        self.rewards[agent] = reward
        self._last_rewarded = agent
        # The acting agent's reward is the only one that is not 0, so accumulating the rewards
        # (PettingZoo's _accumulate_rewards) changes only its sum, which restarts at this step.
        self._cumulative_rewards[agent] = 0.0 + reward
        if self.sim.truncated:
            info = dict(info, episode=self.sim.episode_metrics())
            self.truncations = dict.fromkeys(self.agents, True)
        self.infos = dict.fromkeys(self.agents, info)
        self.agent_selection = self.possible_agents[self.sim.acting]
        if self.render_mode == "human":
            self.render()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self.render_mode == "rgb_array":
            return render_frame(self.sim)
        return None  # "human": pybullet's GUI window shows the bodies as they move

    def close(self) -> None:
        self.sim.close()
