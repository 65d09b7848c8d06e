"""Episodes as tasks of the execution layer (:mod:`agents.execution`): one episode per task, in
this process, a pool of worker processes or on a Ray cluster.

An episode's result depends only on its task (agent, case, seed, overrides), never on which
process or node ran it or in what order."""

from __future__ import annotations

import sys
import time
from typing import Any, Callable, Sequence

import numpy as np

from agents.controllers.episode import run_aec_episode
from agents.controllers.registry import make_controller
from agents.evaluate.metrics import with_aliases
from agents.evaluate.settings import EpisodeRecord, EpisodeTask, EvalSettings, Overrides
from agents.execution import Backend, LocalBackend
from agents.execution.base import raised_at
from marl_vertiport.config import LATEST_RULES

# ============================================================================ worker side

_ENV_CACHE: dict[tuple[str, str, int], Any] = {}


def versioned_env(config: str, overrides: Overrides | dict[str, Any], rules: int = LATEST_RULES,
                  render_mode: str | None = None) -> Any:
    """A new AEC env of a case under the rules of version ``rules`` (``vertiport_v{rules}``)."""
    import importlib

    module = importlib.import_module(f"marl_vertiport.vertiport_v{rules}")
    return module.env(config=config, render_mode=render_mode, **dict(overrides))


def cached_env(config: str, overrides: Overrides, rules: int = LATEST_RULES) -> Any:
    """The AEC env (:func:`versioned_env`) of a case, built once per process (each holds its
    own pybullet client)."""
    key = (config, repr(overrides), rules)
    if key not in _ENV_CACHE:
        _ENV_CACHE[key] = versioned_env(config, overrides, rules)
    return _ENV_CACHE[key]


def _drop_env(config: str, overrides: Overrides, rules: int) -> None:
    env = _ENV_CACHE.pop((config, repr(overrides), rules), None)
    if env is not None:
        env.close()


def close_envs() -> None:
    """Close every env this process has cached."""
    for key in list(_ENV_CACHE):
        _ENV_CACHE.pop(key).close()


def _plain(value: Any) -> Any:
    """numpy scalars and arrays -> Python numbers and lists (for JSON and CSV)."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    return value


def run_task(task: EpisodeTask) -> EpisodeRecord:
    """Run one episode with a fresh controller; errors come back in the record, not raised."""
    start = time.perf_counter()
    try:
        env = cached_env(task.config, task.overrides, task.rules)
        controller = make_controller(task.agent)
        metrics = run_aec_episode(env, controller, seed=task.seed)
    except Exception as exc:  # an illegal action (ValueError), or a controller that crashed
        _drop_env(task.config, task.overrides, task.rules)  # the env stopped mid-episode
        if isinstance(exc, ValueError):
            error = str(exc)
        else:
            error = f"{type(exc).__name__}: {exc} ({raised_at(exc)})"
        return EpisodeRecord(task, error=error, seconds=time.perf_counter() - start)
    plain = with_aliases({k: _plain(v) for k, v in metrics.items()})
    return EpisodeRecord(task, metrics=plain, seconds=time.perf_counter() - start)


def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, file=sys.stderr, unit="episode", disable=not enabled,
                dynamic_ncols=True)


def _describe_failure(record: EpisodeRecord) -> str:
    t = record.task
    return (f"agent {t.agent!r} failed in case {t.config!r} at seed {t.seed} "
            f"(episode {t.episode}): {record.error}")


def run_tasks(tasks: Sequence[EpisodeTask], backend: Backend | None = None,
              progress: bool = True, label: Callable[[EpisodeTask], str] | None = None,
              ) -> tuple[list[EpisodeRecord], str | None]:
    """Run ``tasks`` on ``backend`` (default: this process); stop at the first failure.

    Args:
        label: what the progress bar shows for the last completed task (default: agent and
            case).

    Returns:
        The completed episodes in task order, and the error that stopped the run (None if it
        ran to the end; :data:`INTERRUPTED` after Ctrl-C).
    """
    backend = backend or LocalBackend(1)
    done: dict[int, EpisodeRecord] = {}
    failure: list[str] = []
    bar = _progress(len(tasks), progress)
    label = label or (lambda t: f"{t.agent} / {t.config}")

    def on_result(i: int, record: EpisodeRecord) -> bool:
        if record.error is not None:
            if not failure:
                failure.append(_describe_failure(record))
            return False
        done[i] = record
        bar.set_description(label(record.task), refresh=False)
        bar.update(1)
        return not failure

    try:
        problem = backend.run(run_task, tasks, on_result)
    finally:
        bar.close()
    if problem and not failure:
        failure.append(problem)
    return [done[i] for i in sorted(done)], (failure[0] if failure else None)


def run_episodes(settings: EvalSettings, backend: Backend | None = None,
                 progress: bool = True) -> tuple[list[EpisodeRecord], str | None]:
    """Run every episode of ``settings`` (see :func:`run_tasks`); the completed ones come back
    sorted by (agent, case, episode)."""
    return run_tasks(settings.tasks(), backend, progress)
