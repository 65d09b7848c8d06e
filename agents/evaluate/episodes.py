"""The execution layer: run episodes in this process or a pool of worker processes.

An episode's result depends only on its task (agent, case, seed), never on which process ran
it or in what order."""

from __future__ import annotations

import multiprocessing
import signal
import sys
import time
import traceback
from pathlib import Path
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from agents.controllers.base import run_aec_episode
from agents.controllers.registry import make_controller
from agents.evaluate.settings import (
    EpisodeRecord, EpisodeTask, EvalSettings, INTERRUPTED, Overrides,
)

# ============================================================================ worker side

_ENV_CACHE: dict[tuple[str, str], Any] = {}


def cached_env(config: str, overrides: Overrides) -> Any:
    """The AEC env of a case, built once per process (each holds its own pybullet client)."""
    from marl_vertiport import vertiport_v0

    key = (config, repr(overrides))
    if key not in _ENV_CACHE:
        _ENV_CACHE[key] = vertiport_v0.env(config=config, **dict(overrides))
    return _ENV_CACHE[key]


def _drop_env(config: str, overrides: Overrides) -> None:
    env = _ENV_CACHE.pop((config, repr(overrides)), None)
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


def raised_at(exc: BaseException) -> str:
    """``raised at FILE:LINE in FUNCTION`` of the innermost frame of ``exc``'s traceback (the
    file relative to the working directory when it lies below it)."""
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return "raised at an unknown place"
    last = frames[-1]
    path = Path(last.filename)
    try:
        path = path.resolve().relative_to(Path.cwd())
    except ValueError:
        pass
    return f"raised at {path}:{last.lineno} in {last.name}"


def run_task(task: EpisodeTask) -> EpisodeRecord:
    """Run one episode with a fresh controller; errors come back in the record, not raised."""
    start = time.perf_counter()
    try:
        env = cached_env(task.config, task.overrides)
        controller = make_controller(task.agent)
        metrics = run_aec_episode(env, controller, seed=task.seed)
    except Exception as exc:  # an illegal action (ValueError), or a controller that crashed
        _drop_env(task.config, task.overrides)  # the env stopped mid-episode
        if isinstance(exc, ValueError):
            error = str(exc)
        else:
            error = f"{type(exc).__name__}: {exc} ({raised_at(exc)})"
        return EpisodeRecord(task, error=error, seconds=time.perf_counter() - start)
    plain = {k: _plain(v) for k, v in metrics.items()}
    return EpisodeRecord(task, metrics=plain, seconds=time.perf_counter() - start)


def _worker_init() -> None:
    """Workers ignore Ctrl-C: the parent stops handing out work and lets them finish."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)



def _progress(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, file=sys.stderr, unit="episode", disable=not enabled,
                dynamic_ncols=True)


def _describe_failure(record: EpisodeRecord) -> str:
    t = record.task
    return (f"agent {t.agent!r} failed in case {t.config!r} at seed {t.seed} "
            f"(episode {t.episode}): {record.error}")


def _run_serial(tasks: Sequence[EpisodeTask], on_done: Callable[[EpisodeRecord], bool]) -> None:
    for task in tasks:
        if not on_done(run_task(task)):
            return


def _run_pool(tasks: Sequence[EpisodeTask], workers: int,
              on_done: Callable[[EpisodeRecord], bool]) -> str | None:
    """Run ``tasks`` on ``workers`` spawned processes; stop handing out work as soon as
    ``on_done`` returns False. Returns an error message if the pool itself broke."""
    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
    futures: list[Future] = []
    seen: set[int] = set()
    problem: str | None = None
    try:
        futures = [pool.submit(run_task, task) for task in tasks]
        for i, fut in _completed_in_any_order(futures):
            seen.add(i)
            if not on_done(fut.result()):
                break
    except KeyboardInterrupt:
        problem = INTERRUPTED
    except Exception as exc:  # BrokenProcessPool: a worker died (crash, out of memory)
        problem = f"a worker process failed: {type(exc).__name__}: {exc}"
    finally:
        for fut in futures:
            fut.cancel()
        pool.shutdown(wait=True, cancel_futures=True)
    # Episodes that were already running when the run stopped finished: keep them.
    for i, fut in enumerate(futures):
        if i not in seen and fut.done() and not fut.cancelled() and fut.exception() is None:
            on_done(fut.result())
    return problem


def _completed_in_any_order(futures: list[Future]) -> Iterable[tuple[int, Future]]:
    index = {id(f): i for i, f in enumerate(futures)}
    for fut in as_completed(futures):
        yield index[id(fut)], fut


def run_episodes(settings: EvalSettings, workers: int = 1,
                 progress: bool = True) -> tuple[list[EpisodeRecord], str | None]:
    """Run every episode of ``settings``; stop at the first failure.

    Returns the completed episodes sorted by (agent, case, episode), and the error that stopped
    the run (None if it ran to the end).
    """
    tasks = settings.tasks()
    done: list[EpisodeRecord] = []
    failure: list[str] = []
    bar = _progress(len(tasks), progress)

    def on_done(record: EpisodeRecord) -> bool:
        if record.error is not None:
            if not failure:
                failure.append(_describe_failure(record))
            return False
        done.append(record)
        bar.set_description(f"{record.task.agent} / {record.task.config}", refresh=False)
        bar.update(1)
        return not failure

    try:
        if workers <= 1:
            try:
                _run_serial(tasks, on_done)
            except KeyboardInterrupt:
                failure.append(INTERRUPTED)
        else:
            problem = _run_pool(tasks, min(workers, len(tasks)), on_done)
            if problem and not failure:
                failure.append(problem)
    finally:
        bar.close()
    order = {(a, c): (i, j) for i, a in enumerate(settings.agents)
             for j, c in enumerate(settings.configs)}
    done.sort(key=lambda r: (*order[(r.task.agent, r.task.config)], r.task.episode))
    return done, (failure[0] if failure else None)


