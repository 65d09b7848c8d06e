"""The one episode loop: a controller drives a day of either env, with hooks around each step.

Every tool that plays days goes through :func:`run_episode`: the evaluation's episodes, the
sweeps, rendering, the soak, the charger study, the warm start's demonstration days and the
ensemble's days, the benchmark's recording of traffic and its planner timing. Only the
benchmark's timed replay keeps a bare loop of its own (:mod:`agents.bench.replay`): it measures
the env alone.

A day: ``env.reset(seed)``; the controller's ``reset(seed)`` and, for a controller that plans
with the simulator, ``bind(sim)`` (:func:`prepare`); then, step by step, ``before_step(agent,
observation, env)``, the controller's ``act(observation)``, checked against the mask
(:func:`check_legal`: an illegal action raises ``ValueError`` naming the controller, and the
env is not stepped), ``env.step(action)`` and ``after_step(agent, action, env)``. The AEC env
(PettingZoo) and the single-agent env (Gymnasium) give the same observations, so the same
controller and hooks run on both.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from marl_vertiport.sim.schema import format_actions

#: ``before_step(agent, observation, env)``, before the controller acts.
BeforeStep = Callable[[str, dict, Any], None]
#: ``after_step(agent, action, env)``, after the env stepped.
AfterStep = Callable[[str, int, Any], None]


def action_names(env: Any) -> list[str]:
    """The names of ``env``'s actions (either API), for error messages."""
    sim = env.unwrapped.sim
    return sim.actions.names(sim.layout)


def check_legal(policy: Any, agent: str, action: Any, mask: np.ndarray,
                names: list[str]) -> int:
    """``action`` as an int if ``mask`` allows it, else ``ValueError`` naming the controller,
    the agent and the legal actions (in the env's own format, :func:`format_actions`)."""
    try:
        a = int(action)
    except (TypeError, ValueError):
        a = None
    if a is not None and a == action and 0 <= a < len(mask) and mask[a]:
        return a
    name = getattr(policy, "name", type(policy).__name__)
    legal = format_actions(np.flatnonzero(mask), names)
    if a is None:
        raise ValueError(f"controller {name!r} returned {action!r} for {agent}, not an integer "
                         f"action; legal actions were {legal}")
    raise ValueError(f"controller {name!r} returned the illegal action {action!r} for "
                     f"{agent}; legal actions were {legal}")


def prepare(policy: Any, env: Any, seed: int) -> None:
    """Start ``policy``'s episode: ``reset(seed)``, and ``bind(sim)`` for a model-based
    controller that plans with the simulator (such as :class:`agents.controllers.planner.PlannerController`)."""
    if hasattr(policy, "reset"):
        policy.reset(seed=seed)
    if hasattr(policy, "bind"):
        policy.bind(env.unwrapped.sim)


def run_episode(env: Any, policy: Any, seed: int, *, before_step: BeforeStep | None = None,
                after_step: AfterStep | None = None, max_steps: int | None = None
                ) -> dict[str, Any]:
    """One day of ``env`` (the AEC env or the single-agent env) driven by ``policy``; see the
    module docstring. ``max_steps`` ends the day early (the start of a day). Returns the
    episode metrics, of the steps played."""
    names = action_names(env)
    steps = 0
    if hasattr(env, "agent_iter"):  # PettingZoo AEC: each agent's turn in round-robin order
        env.reset(seed=seed)
        prepare(policy, env, seed)
        for agent in env.agent_iter():
            obs, _, termination, truncation, _ = env.last()
            if termination or truncation:
                env.step(None)
                continue
            if max_steps is not None and steps >= max_steps:
                break
            steps = _step(env, policy, agent, obs, names, before_step, after_step, steps)
    else:  # Gymnasium: the acting eVTOL's observation, its name in the step's info
        obs, info = env.reset(seed=seed)
        prepare(policy, env, seed)
        truncated = terminated = False
        while not (truncated or terminated) and (max_steps is None or steps < max_steps):
            agent = info.get("agent", "the acting eVTOL")
            if before_step is not None:
                before_step(agent, obs, env)
            action = check_legal(policy, agent, policy.act(obs), obs["action_mask"], names)
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            if after_step is not None:
                after_step(agent, action, env)
    return env.unwrapped.sim.episode_metrics()


def _step(env: Any, policy: Any, agent: str, obs: dict, names: list[str],
          before_step: BeforeStep | None, after_step: AfterStep | None, steps: int) -> int:
    if before_step is not None:
        before_step(agent, obs, env)
    action = check_legal(policy, agent, policy.act(obs), obs["action_mask"], names)
    env.step(action)
    if after_step is not None:
        after_step(agent, action, env)
    return steps + 1


def run_aec_episode(env: Any, policy: Any, seed: int, on_step: AfterStep | None = None
                    ) -> dict[str, Any]:
    """:func:`run_episode` on the AEC env, ``on_step`` after each step."""
    return run_episode(env, policy, seed, after_step=on_step)


def run_gym_episode(env: Any, policy: Any, seed: int) -> dict[str, Any]:
    """:func:`run_episode` on the single-agent env."""
    return run_episode(env, policy, seed)
