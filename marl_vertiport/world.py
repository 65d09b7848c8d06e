"""What both envs build the same way from a config: the simulator, its observation builder and,
in a window, the scenery."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from marl_vertiport.config import (
    EnvConfig, UnexpectedKeywordError, UnknownKeyError, load_config, with_rules,
)
from marl_vertiport.render import draw_scenery
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.physics import display_available
from marl_vertiport.spaces import ObservationBuilder


@dataclass
class World:
    """One env's config, simulator and observation builder."""

    config: EnvConfig
    sim: VertiportSim
    builder: ObservationBuilder


def make_world(config: str | EnvConfig | dict | None, render_mode: str | None,
               render_modes: list[str], owner: str, rules: int, /, **overrides: Any) -> World:
    """Validate ``render_mode`` against ``render_modes``, load the config with ``overrides``
    (the keywords of the env ``owner``, a class name for errors) under the rules of version
    ``rules`` (:func:`~marl_vertiport.config.with_rules`), and build the simulator (pybullet's
    window for ``"human"`` where a display exists).

    Raises:
        ValueError: an unknown render mode.
        UnexpectedKeywordError: a keyword that is no config key (a ``ConfigError`` and a
            ``TypeError``).
        ConfigError: a bad config or override value.
    """
    if render_mode is not None and render_mode not in render_modes:
        raise ValueError(f"render_mode {render_mode!r} is not one of {render_modes} or None")
    try:
        cfg = load_config(config, **overrides)
    except UnknownKeyError as exc:
        if exc.keyword is None:  # a key of the config file or dict itself
            raise
        raise UnexpectedKeywordError.of(owner, exc) from None
    cfg = with_rules(cfg, rules)
    sim = VertiportSim(cfg, gui=render_mode == "human" and display_available())
    builder = ObservationBuilder(sim)
    if sim.physics.gui:
        draw_scenery(sim)
    return World(cfg, sim, builder)


def attach_world(env: Any, config: str | EnvConfig | dict | None, render_mode: str | None,
                 overrides: dict[str, Any]) -> World:
    """Build ``env``'s world (:func:`make_world` with the render modes of its ``metadata``, its
    class name and its ``RULES``) and set ``env.config``, ``env.sim``, ``env._builder`` and
    ``env.render_mode``: what every env of the package does first."""
    world = make_world(config, render_mode, env.metadata["render_modes"], type(env).__name__,
                       env.RULES, **overrides)
    env.config, env.sim, env._builder = world.config, world.sim, world.builder
    env.render_mode = render_mode
    return world


def agent_names(n: int) -> tuple[list[str], dict[str, int]]:
    """The multi-agent envs' agents, ``evtol_0 .. evtol_{n-1}``, and each one's vehicle index."""
    names = [f"evtol_{i}" for i in range(n)]
    return names, {a: i for i, a in enumerate(names)}

