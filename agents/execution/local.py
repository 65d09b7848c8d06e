"""The local backend: tasks in this process, or in a pool of spawned worker processes on this
machine. Needs nothing beyond the project's own dependencies."""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Sequence

from agents.execution.base import (
    INTERRUPTED, Backend, OnResult, first_line, call_task, task_failure,
)


def _worker_init() -> None:
    """Workers ignore Ctrl-C: the driver stops handing out work and lets them finish. On Linux
    they also end with the driver: a driver killed outright (SIGTERM, SIGKILL, out of memory)
    cannot shut its pool down, and its workers would otherwise go on with the tasks queued."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _end_with_parent()


def _end_with_parent() -> None:
    """Ask the kernel to send this process SIGTERM when the thread that started it ends
    (``prctl(PR_SET_PDEATHSIG)``; the driver's thread waits in :meth:`LocalBackend.run` for as
    long as the pool lives). Elsewhere than Linux: nothing."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() == 1:  # the driver died before the request was made
        os._exit(1)


class LocalBackend(Backend):
    """``workers`` processes (default: the CPU cores); 1 runs every task in this process."""

    name = "local"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1

    @property
    def slots(self) -> int:
        return self.workers

    def describe(self) -> str:
        return ("local: this process" if self.workers == 1
                else f"local: {self.workers} worker processes")

    def run(self, fn: Callable[[Any], Any], tasks: Sequence[Any],
            on_result: OnResult) -> str | None:
        if self.workers <= 1 or len(tasks) <= 1:
            return self._run_here(fn, tasks, on_result)
        return self._run_pool(fn, tasks, on_result, min(self.workers, len(tasks)))

    @staticmethod
    def _run_here(fn: Callable[[Any], Any], tasks: Sequence[Any],
                  on_result: OnResult) -> str | None:
        for i, task in enumerate(tasks):
            try:
                result = call_task(fn, task)
            except KeyboardInterrupt:
                return INTERRUPTED
            except Exception as exc:
                return task_failure(i, exc)
            try:
                if not on_result(i, result):
                    return None
            except KeyboardInterrupt:
                return INTERRUPTED
        return None

    @staticmethod
    def _run_pool(fn: Callable[[Any], Any], tasks: Sequence[Any], on_result: OnResult,
                  workers: int) -> str | None:
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
        futures: list[Future] = []
        index: dict[int, int] = {}
        seen: set[int] = set()
        problem: str | None = None
        try:
            futures = [pool.submit(call_task, fn, task) for task in tasks]
            index = {id(f): i for i, f in enumerate(futures)}
            for fut in as_completed(futures):
                i = index[id(fut)]
                seen.add(i)
                exc = fut.exception()
                if exc is not None:
                    problem = _pool_failure(i, exc)
                    break
                if not on_result(i, fut.result()):
                    break
        except KeyboardInterrupt:
            problem = INTERRUPTED
            under_way = sum(1 for f in futures if f.running())
            if under_way:
                print(f"Ctrl-C: waiting for the {under_way} task(s) under way to finish, to keep "
                      "their results; Ctrl-C again stops them now", file=sys.stderr, flush=True)
        finally:
            for fut in futures:
                fut.cancel()
            try:
                pool.shutdown(wait=True, cancel_futures=True)
            except KeyboardInterrupt:  # a second Ctrl-C: the tasks under way are dropped
                problem = INTERRUPTED
                _stop_workers(pool)
        # Tasks that were already running when the run stopped finished: hand them over.
        for i, fut in enumerate(futures):
            if i not in seen and fut.done() and not fut.cancelled() and fut.exception() is None:
                on_result(i, fut.result())
        return problem


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """End the pool's workers now (their tasks are lost) and wait for the pool to close.
    ``ProcessPoolExecutor`` has no public way to do this before Python 3.14."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def _pool_failure(index: int, exc: BaseException) -> str:
    from concurrent.futures.process import BrokenProcessPool

    if isinstance(exc, BrokenProcessPool):  # a worker died (crash, out of memory)
        return f"a worker process failed: {first_line(exc)}"
    return task_failure(index, exc)
