"""The PettingZoo Parallel env's implementation, shared by its versions
(:func:`marl_vertiport.vertiport_v1.parallel_env`, :func:`marl_vertiport.vertiport_v0.parallel_env`):
the same simulator as the AEC env, in which one parallel step is one ATC turn.

Every live agent submits an action at every step, but only the agent whose turn it is (the
AEC env's ``agent_selection``, here :attr:`VertiportParallel.acting_agent`) is given an
instruction: its observation carries its full mask, exactly as in the AEC env. Every other
agent has one legal action, the no-op ``continue`` (:attr:`VertiportParallel.noop_action`, index
``2 + P``): its mask has that action alone, and any other action raises
:class:`~marl_vertiport.sim.core.IllegalActionError` naming the agent, before anything changes.
An agent missing from the actions dict is taken to wait; the acting agent must be present.

Parity with the AEC env, step by step (``tests/envs/test_parity.py``): the same observation
graphs for every agent, the acting agent's mask, the rewards (the acting agent's, 0 for the
others), truncations, terminations (never) and infos (one dict shared by all agents, with
``info["episode"]`` at the last step). Only the masks of agents not acting differ: the AEC
env's ``observe`` gives them the mask they would have if it were their turn.

``is_parallelizable`` stays ``False`` on the AEC env: PettingZoo's ``aec_to_parallel`` would
make one parallel step a whole round of N turns with every action chosen at the start of the
round, so a later agent's action could be masked out by the time its turn comes, and a
vertiport that passes over vehicles without a decision (``atc.skip_agents_without_decision``)
breaks its cycle. Use this env instead (docs/ecosystem.md argues the reading).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from marl_vertiport.aec_env import VertiportAEC
from marl_vertiport.config import LATEST_RULES, EnvConfig
from marl_vertiport.render import render_frame
from marl_vertiport.sim.core import IllegalActionError
from marl_vertiport.spaces import LegalDiscrete
from marl_vertiport.world import agent_names, attach_world

__all__ = ["VertiportParallel"]


class VertiportParallel(ParallelEnv):
    """Parallel env under the rules of version :attr:`RULES`; see the module docstring.

    Args:
        config: a config object, a dict, a YAML path, or a name in ``configs/env/``.
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        **overrides: dotted config keys or whole sections, as for the AEC env.
    """

    #: The rules version (marl_vertiport/config/rules.py).
    RULES = LATEST_RULES
    metadata = dict(VertiportAEC.metadata, is_parallelizable=True)

    def __init__(self, config: str | EnvConfig | dict | None = None,
                 render_mode: str | None = None, **overrides: Any) -> None:
        attach_world(self, config, render_mode, overrides)
        self.possible_agents, self.agent_name_mapping = agent_names(self.sim.n)
        #: The one legal action of an agent whose turn it is not: ``continue`` (index 2 + P).
        self.noop_action = int(self.sim.actions.continue_)
        noop = np.zeros(self.sim.actions.n, dtype=np.int8)
        noop[self.noop_action] = 1
        noop.setflags(write=False)
        self._noop_mask = noop
        self.observation_spaces = dict.fromkeys(self.possible_agents,
                                                self._builder.observation_space)
        # sample() without a mask draws among the agent's legal actions now (the no-op where it
        # is not its turn), so PettingZoo's seed test and random play are always legal.
        self.action_spaces = {a: LegalDiscrete(self.sim.actions.n, self._mask_fn(v))
                              for a, v in self.agent_name_mapping.items()}
        self.state_space = self._builder.state_space
        self._rng: np.random.Generator | None = None
        self.agents: list[str] = []

    def _mask_fn(self, v: int):
        return lambda: self.action_mask(v)

    def observation_space(self, agent: str):
        return self.observation_spaces[agent]

    def action_space(self, agent: str):
        return self.action_spaces[agent]

    @property
    def acting_agent(self) -> str:
        """The agent whose turn it is: the one whose action the next :meth:`step` applies."""
        self._require_reset("acting_agent")
        return self.possible_agents[self.sim.acting]

    def action_mask(self, v: int) -> np.ndarray:
        """Legal actions of vehicle ``v`` in this env (int8 ``(A,)``): its simulator mask on
        its turn, the no-op alone otherwise."""
        if self._rng is None:
            return np.ones(self.sim.actions.n, dtype=np.int8)  # before reset: any index
        if v == self.sim.acting:
            return self.sim.action_mask(v).copy()
        return self._noop_mask.copy()

    def _require_reset(self, what: str) -> None:
        if self._rng is None:
            raise RuntimeError(f"reset() must be called before {what}")

    def _observations(self) -> dict[str, dict]:
        acting = self.sim.acting
        observe = self._builder.observe
        return {a: observe(v) if v == acting else observe(v, action_mask=self._noop_mask)
                for a, v in self.agent_name_mapping.items()}

    def reset(self, seed: int | None = None,
              options: dict | None = None) -> tuple[dict[str, dict], dict[str, dict]]:
        if seed is not None or self._rng is None:
            self._rng, _ = seeding.np_random(seed)
        self.sim.reset(self._rng)
        self.agents = self.possible_agents[:]
        return self._observations(), {a: {} for a in self.agents}

    def _acting_action(self, actions: Any) -> Any:
        """The acting agent's action from ``actions``, after checking every other entry."""
        if not isinstance(actions, dict):
            raise TypeError(f"step() takes a dict of actions, agent -> action; got "
                            f"{type(actions).__name__}")
        acting = self.acting_agent
        for agent, action in actions.items():
            if agent == acting:
                continue
            if agent not in self.agent_name_mapping:
                raise KeyError(f"unknown agent {agent!r}; the agents are "
                               f"{', '.join(self.possible_agents)}")
            if action is None:
                continue
            try:
                self.sim.check_action(self.agent_name_mapping[agent], action, self._noop_mask)
            except IllegalActionError as exc:
                raise IllegalActionError(
                    f"{exc}: it is the turn of {acting}, and an agent whose turn it is not may "
                    f"only wait") from None
        if acting not in actions or actions[acting] is None:
            raise KeyError(f"no action for {acting}, whose turn it is (env.acting_agent)")
        return actions[acting]

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Apply the acting agent's action, advance the world one step.

        Raises:
            RuntimeError: before :meth:`reset` or after the episode's end.
            KeyError: no action for the acting agent, or an unknown agent.
            IllegalActionError: the acting agent's action is masked out, or another agent's is
                not the no-op; nothing changes.
        """
        self._require_reset("step()")
        if not self.agents:
            raise RuntimeError(f"the episode ended (truncated after {self.sim.step_count} "
                               "steps); call reset() to start another")
        acting = self.acting_agent
        reward, info = self.sim.step(self._acting_action(actions))
        rewards = dict.fromkeys(self.agents, 0.0)
        rewards[acting] = reward
        truncated = self.sim.truncated
        if truncated:
            info = dict(info, episode=self.sim.episode_metrics())
        terminations = dict.fromkeys(self.agents, False)
        truncations = dict.fromkeys(self.agents, truncated)
        infos = dict.fromkeys(self.agents, info)
        observations = self._observations()
        if truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def state(self) -> dict:
        """The global, noise-free graph, as the AEC env's ``state()`` (after ``reset()``)."""
        self._require_reset("state()")
        return self._builder.state()

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return render_frame(self.sim)
        return None  # "human": pybullet's GUI window shows the bodies as they move

    def close(self) -> None:
        self.sim.close()
