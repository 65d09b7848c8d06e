"""The ray backend: tasks on a Ray cluster, one machine or many.

Each task is a Ray task of one CPU, spread over the nodes. A task whose worker process or node
is lost is retried elsewhere (``max_retries``): the run completes with the same results, since a
task's result depends only on the task. The driver keeps a bounded window of tasks in flight
(twice the cluster's CPUs, re-read as nodes join or leave), so that a study of any size needs
little memory and stops quickly.

Ray is an optional extra (``pip install -e '.[ray]'``); this module imports it only when a
backend is made, and says how to install it when it is missing.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
from typing import Any, Callable, Sequence

from agents.execution.base import (
    INTERRUPTED, RAY_EXTRA_HINT, Backend, BackendError, OnResult, first_line, call_task,
)

#: Object store of a Ray instance this backend starts itself (results are fetched as they
#: arrive, so it only ever holds a window of them).
LOCAL_OBJECT_STORE_BYTES = 512 * 1024 ** 2
#: How long to wait for a cluster's address to answer before giving up.
CONNECT_TIMEOUT_S = 5.0
#: Retries of a task whose worker process or node was lost.
MAX_RETRIES = 3


def import_ray() -> Any:
    """The ``ray`` module, or :class:`BackendError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise BackendError(f"the ray backend needs the optional ray extra: {RAY_EXTRA_HINT}") from None
    return ray


def _call(fn: Callable[[Any], Any], task: Any) -> tuple[str, Any]:
    """Runs in a Ray worker: ``(the node it ran on, fn(task))``."""
    import ray

    return ray.get_runtime_context().get_node_id(), call_task(fn, task)


class RayBackend(Backend):
    """Tasks on the Ray cluster at ``address`` (default ``$RAY_ADDRESS``), or on a Ray instance
    of its own on this machine with ``workers`` CPUs when there is neither. A driver that has
    already called ``ray.init`` is used as it is.

    After :meth:`run`, :attr:`placements` holds, per task index, the id of the node whose
    result was kept."""

    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None,
                 max_retries: int = MAX_RETRIES) -> None:
        ray = import_ray()
        self._ray = ray
        self.max_retries = max_retries
        self.placements: dict[int, str] = {}
        self._owns_connection = False
        if ray.is_initialized():
            return
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no reports to the internet
        target = address or os.environ.get("RAY_ADDRESS")
        common = {"logging_level": logging.WARNING, "log_to_driver": False}
        if target:
            _check_reachable(target)
        try:
            if target:
                ray.init(address=target, **common)
            else:
                # Workers of a local instance see this process's import path, as the local
                # backend's spawned processes do (controllers given by import path).
                path = os.pathsep.join(p for p in sys.path if p and os.path.isdir(p))
                ray.init(num_cpus=workers or os.cpu_count() or 1, include_dashboard=False,
                         object_store_memory=LOCAL_OBJECT_STORE_BYTES,
                         runtime_env={"env_vars": {"PYTHONPATH": path}}, **common)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"at {target}" if target else "on this machine"
            raise BackendError(f"could not start or join a Ray cluster {where}: "
                               f"{first_line(exc)}") from None
        self._owns_connection = True

    @property
    def slots(self) -> int:
        return max(1, int(self._ray.cluster_resources().get("CPU", 1)))

    def describe(self) -> str:
        nodes = [n for n in self._ray.nodes() if n.get("Alive")]
        return f"ray: {len(nodes)} node{'s' if len(nodes) != 1 else ''}, {self.slots} CPUs"

    def run(self, fn: Callable[[Any], Any], tasks: Sequence[Any],
            on_result: OnResult) -> str | None:
        ray = self._ray
        remote = ray.remote(_call).options(num_cpus=1, max_retries=self.max_retries,
                                           retry_exceptions=False, scheduling_strategy="SPREAD")
        self.placements = {}
        in_flight: dict[Any, int] = {}
        next_task = 0
        problem: str | None = None
        stopped = False
        try:
            while next_task < len(tasks) or in_flight:
                window = 2 * self.slots
                while next_task < len(tasks) and len(in_flight) < window:
                    in_flight[remote.remote(fn, tasks[next_task])] = next_task
                    next_task += 1
                done, _ = ray.wait(list(in_flight), num_returns=1)
                for ref in done:
                    i = in_flight.pop(ref)
                    try:
                        node, result = ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        problem = _ray_failure(i, exc)
                        stopped = True
                        break
                    self.placements[i] = node
                    if not on_result(i, result):
                        stopped = True
                        break
                if stopped:
                    break
        except KeyboardInterrupt:
            problem = INTERRUPTED
        finally:
            if in_flight:
                self._finish(in_flight, on_result)
        return problem

    def _finish(self, in_flight: dict[Any, int], on_result: OnResult) -> None:
        """After a stop: hand over the tasks that had finished, cancel the rest."""
        ray = self._ray
        ready, rest = ray.wait(list(in_flight), num_returns=len(in_flight), timeout=0)
        for ref in ready:
            try:
                node, result = ray.get(ref)
            except ray.exceptions.RayError:
                continue
            self.placements[in_flight[ref]] = node
            on_result(in_flight[ref], result)
        for ref in rest:
            ray.cancel(ref)

    def close(self) -> None:
        if self._owns_connection and self._ray.is_initialized():
            self._ray.shutdown()
        self._owns_connection = False


def _check_reachable(address: str) -> None:
    """Fail at once, not after Ray's minute of retries, when nothing listens at a
    ``HOST:PORT`` address (``auto`` and ``ray://`` addresses are left to Ray)."""
    host, sep, port = address.rpartition(":")
    if address == "auto" or "://" in address or not sep or not port.isdigit():
        return
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise BackendError(f"no Ray cluster answers at {address}: {exc.strerror or exc} (start "
                           f"one with `ray start --head`, see docs/scaling.md)") from None


def _ray_failure(index: int, exc: BaseException) -> str:
    """A task whose ``fn`` raised (Ray wraps the exception: name the original), or one lost
    with its worker or node more often than it may be retried."""
    cause = getattr(exc, "cause", None)
    shown = cause if isinstance(cause, BaseException) else exc
    return f"task {index} failed on the Ray cluster: {first_line(shown)}"
