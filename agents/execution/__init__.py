"""The execution layer: independent tasks (evaluation episodes, days of demonstrations) run on
one of two backends, and each result comes back to the driver as it completes.

One job per module:

* ``base``: the interface every backend keeps and its errors;
* ``choice``: a backend by name or from the command-line options ``--backend`` and
  ``--ray-address``;
* ``local``: this process, or a pool of worker processes on this machine (the default);
* ``ray_backend``: tasks on a Ray cluster, one machine or many (the optional ``ray`` extra,
  ``pip install -e '.[ray]'``).

A task's result depends only on the task, never on the backend, the process that ran it or
the order in which tasks finish; only the driver writes results.
"""

from agents.execution.base import INTERRUPTED, RAY_EXTRA_HINT, Backend, BackendError
from agents.execution.choice import (
    BACKENDS, add_backend_arguments, backend_from_args, make_backend,
)
from agents.execution.local import LocalBackend

__all__ = [
    "BACKENDS", "INTERRUPTED", "RAY_EXTRA_HINT", "Backend", "BackendError", "LocalBackend",
    "add_backend_arguments", "backend_from_args", "make_backend",
]
