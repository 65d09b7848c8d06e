"""One evaluation from settings to summary: check the input, run the episodes, summarise; or of
a controller object in memory beside rules (:func:`evaluate_controller`)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from agents.common.provenance import provenance
from agents.common.seeds import EVAL_SEEDS
from agents.controllers.registry import AgentSpecError, in_memory, make_controller
from agents.evaluate.settings import EvalSettings, Evaluation, InputError
from agents.evaluate.episodes import cached_env, close_envs, run_episodes
from agents.evaluate.stats import scalar_metrics, summarize
from agents.evaluate.unforced import unforced_rows, with_unforced
from agents.execution import Backend, LocalBackend

def check_agent(spec: str) -> None:
    """Build the controller of agent ``spec`` once, before anything runs.

    Raises:
        InputError: an unknown agent, an import path that does not load, or a controller
            whose construction failed, named.
    """
    try:
        make_controller(spec)
    except AgentSpecError as exc:
        raise InputError(str(exc)) from None
    except Exception as exc:  # the class loaded but could not be built
        raise InputError(f"agent {spec!r}: building the controller failed: "
                         f"{type(exc).__name__}: {exc}") from None


def validate(settings: EvalSettings) -> dict[str, list[str]]:
    """Check every agent and case before anything runs; return each case's action names.

    Raises:
        InputError: an unknown agent, an import path that does not load, a bad config or
            override, or an episode count outside ``1 .. len(EVAL_SEEDS)``.
    """
    from marl_vertiport.config import ConfigError, load_config

    if settings.first_seed is None and not 1 <= settings.episodes <= len(EVAL_SEEDS):
        raise InputError(f"--episodes must be between 1 and {len(EVAL_SEEDS)}, "
                         f"got {settings.episodes}")
    if settings.bootstrap < 1:
        raise InputError(f"--bootstrap must be >= 1, got {settings.bootstrap}")
    if not settings.agents or not settings.configs:
        raise InputError("at least one agent and one config are needed")
    for spec in settings.agents:
        check_agent(spec)
    names: dict[str, list[str]] = {}
    for config in settings.configs:
        try:
            load_config(config, **dict(settings.overrides))
        except (ConfigError, OSError) as exc:
            raise InputError(f"config {config!r}: {exc}") from None
        sim = cached_env(config, settings.overrides).unwrapped.sim
        names[config] = list(sim.actions.names(sim.layout))
    return names


def evaluate(settings: EvalSettings | Any, workers: int = 1, progress: bool = True,
             action_names: dict[str, list[str]] | None = None,
             backend: Backend | None = None, **controller_options: Any) -> Evaluation:
    """Validate, run every episode and summarise (the episode metrics, then the unforced losses
    across agents, :mod:`agents.evaluate.unforced`). Raises :class:`InputError` on bad input.

    The episodes run on ``backend`` (:mod:`agents.execution`), by default on ``workers`` local
    processes (1: this process); the results do not depend on which.

    ``settings`` may instead be a controller object (anything with ``act``): then this is
    :func:`evaluate_controller`, with ``controller_options`` its keywords."""
    if not isinstance(settings, EvalSettings):
        return evaluate_controller(settings, progress=progress, **controller_options)
    if controller_options:
        raise TypeError(f"evaluate(settings) takes no {sorted(controller_options)}")
    if action_names is None:
        action_names = validate(settings)
    made_with = provenance(settings.agents)  # the code and checkpoints as they are now
    made_with["env"] = {"rules": settings.rules}
    start = time.perf_counter()
    try:
        records, error = run_episodes(settings, backend or LocalBackend(workers), progress)
    finally:
        close_envs()
    metrics = scalar_metrics(records)
    # The unforced losses compare agents on the same days: made once every day is played.
    summary = with_unforced(summarize(records, settings, metrics),
                            unforced_rows(records, settings))
    return Evaluation(settings, records, action_names, metrics, summary, error,
                      seconds=time.perf_counter() - start, provenance=made_with)




def evaluate_controller(controller: Any, *, name: str | None = None,
                        against: Sequence[str] = ("dispatcher",),
                        configs: Sequence[str] = ("paper_uncertain",), episodes: int = 10,
                        first_seed: int | None = None,
                        overrides: Sequence[tuple[str, Any]] = (),
                        out: str | Path | None = None, progress: bool = True) -> Evaluation:
    """Evaluate ``controller``, an object of this process with ``act(observation) -> int``
    (a trained policy in memory, say), beside the controllers ``against`` (specs: the
    dispatcher by default, the strongest rule), on the same days: ``configs`` x the first
    ``episodes`` evaluation seeds (or ``first_seed ..``). Every episode runs in this process
    (an object in memory does not travel to workers); ``controller.reset(seed)`` and
    ``bind(sim)``, where it has them, are called at the start of each day.

    ``name`` labels it in the tables (default: its ``name`` attribute, else its class's
    name). With ``out``, the run's files are written there as ``marl-vertiport evaluate``
    writes them; ``results.json`` records that the controller was an object in memory (it
    cannot be rebuilt from the file).

    Raises:
        InputError: ``name`` is taken by another spec, ``controller`` has no ``act``, or an
            input of :func:`evaluate` is bad.
    """
    from agents.evaluate.report import write_outputs

    label = name or getattr(controller, "name", None)
    if not isinstance(label, str) or label in ("", "controller"):
        label = type(controller).__name__
    try:
        with in_memory(label, controller):
            settings = EvalSettings(agents=(label, *against), configs=tuple(configs),
                                    episodes=episodes, first_seed=first_seed,
                                    overrides=tuple(overrides))
            evaluation = evaluate(settings, progress=progress, backend=LocalBackend(1))
    except AgentSpecError as exc:
        raise InputError(str(exc)) from None
    cls = type(controller)
    evaluation.provenance.setdefault("controllers", {})[label] = {
        "in_memory": f"{cls.__module__}.{cls.__qualname__}"}
    if out is not None:
        write_outputs(evaluation, Path(out), f"evaluate_controller({label!r}) in Python")
    return evaluation
