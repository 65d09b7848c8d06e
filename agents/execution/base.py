"""What every backend keeps: run ``fn(task)`` for each task, hand each result to the driver as
it completes, stop handing out work when the driver says so or on Ctrl-C; and its errors.

Every backend runs a task through :func:`call_task`, which gives it the same start wherever it
runs: in the driver's own process, in a worker that has run other tasks before, or on another
node. That is what makes a result depend on the task alone, and a training run the same on one
worker as on many (docs/training.md, "Reproducibility").
"""

from __future__ import annotations

import random
import sys
import traceback
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, Callable, Sequence

#: What :meth:`Backend.run` returns when Ctrl-C stopped it (exit code 130 rather than 1).
INTERRUPTED = "interrupted (Ctrl-C)"
#: How to get the ray backend, for its one-line error.
RAY_EXTRA_HINT = "pip install -e '.[ray]' (in a checkout) or pip install 'marl_vertiport[ray]'"

#: ``on_result(index of the task, its result) -> go on?``, called in the driver.
OnResult = Callable[[int, Any], bool]
#: The seed of torch's, NumPy's and Python's global generators at the start of every task. In
#: a new process they are seeded from the operating system; a task that drew from one would then
#: differ from run to run. The project's tasks draw from generators of their own, seeded by the
#: task; a task that did draw from a global one still gives the same result on every backend.
TASK_SEED = 0


def call_task(fn: Callable[[Any], Any], task: Any) -> Any:
    """``fn(task)`` from the same start in every process, leaving the caller's process as it
    found it.

    Before the task, torch's (where torch is loaded), NumPy's and Python's global generators
    are seeded with :data:`TASK_SEED`; after it, the caller's generator states and torch thread
    count are restored (a task sets its own thread count, as the demonstration days do). So a
    task's result does not depend on which process runs it or what ran there before, and a
    task run in the driver's own process (one worker) leaves the driver's later draws, such as
    PPO's, as they are when the task runs in a worker. torch and NumPy are looked up, never
    imported, here.
    """
    torch, np = sys.modules.get("torch"), sys.modules.get("numpy")
    saved_torch = (torch.get_rng_state(), torch.get_num_threads()) if torch is not None else None
    saved_numpy = np.random.get_state() if np is not None else None
    saved_random = random.getstate()
    if torch is not None:
        torch.manual_seed(TASK_SEED)
    if np is not None:
        np.random.seed(TASK_SEED)
    random.seed(TASK_SEED)
    try:
        return fn(task)
    finally:
        random.setstate(saved_random)
        if saved_numpy is not None:
            np.random.set_state(saved_numpy)
        if saved_torch is not None:
            torch.set_rng_state(saved_torch[0])
            if torch.get_num_threads() != saved_torch[1]:
                torch.set_num_threads(saved_torch[1])


class BackendError(RuntimeError):
    """A backend that cannot be used: the ray extra is missing, no Ray cluster answers at the
    address, or an option that does not fit the backend. Nothing was run."""


class Backend(ABC):
    """Runs independent tasks and hands their results to the driver.

    ``fn`` must be a module-level function (it travels to other processes by name) and
    ``tasks`` picklable values; ``fn(task)`` must depend on nothing but ``task``, so that the
    results are the same on every backend.
    """

    name = ""

    @abstractmethod
    def run(self, fn: Callable[[Any], Any], tasks: Sequence[Any],
            on_result: OnResult) -> str | None:
        """Run ``fn(task)`` for every task; call ``on_result(i, result)`` in this process as
        each task ``tasks[i]`` completes, in any order.

        Stops handing out tasks as soon as ``on_result`` returns False. On Ctrl-C it stops
        too, and the tasks that had already finished are still handed over.

        Returns:
            None when every task ran (or ``on_result`` stopped the run), :data:`INTERRUPTED`
            after Ctrl-C, or a one-line description of what broke: a task that raised, or a
            worker or node lost for good.
        """

    @property
    @abstractmethod
    def slots(self) -> int:
        """How many tasks can run at once now."""

    def describe(self) -> str:
        """Where the tasks run, in a few words (for progress output and result files)."""
        return self.name

    def close(self) -> None:
        """Release what the backend started (worker processes, a Ray instance of its own)."""

    def __enter__(self) -> "Backend":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def first_line(exc: BaseException) -> str:
    """``TypeName: first line of the message`` of an exception."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


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


def task_failure(index: int, exc: BaseException) -> str:
    """The one line :meth:`Backend.run` returns for a task whose ``fn`` raised."""
    return f"task {index} failed: {first_line(exc)} ({raised_at(exc)})"
