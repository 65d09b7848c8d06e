"""The choice of backend: by name, and from the command-line options every command that runs
tasks shares (``--backend``, ``--ray-address``)."""

from __future__ import annotations

import argparse

from agents.execution.base import Backend, BackendError

#: The backends, by ``--backend`` name.
BACKENDS = ("local", "ray")


def make_backend(name: str = "local", workers: int | None = None,
                 address: str | None = None) -> Backend:
    """The backend called ``name``.

    Args:
        name: ``local`` (this process when ``workers`` is 1, else a pool of ``workers``
            processes) or ``ray``.
        workers: local: worker processes (default: the CPU cores). ray: the CPUs of the Ray
            instance it starts on this machine when it joins no cluster (default: the cores).
        address: ray only: the cluster to join (``auto``, ``HOST:PORT`` or ``ray://...``);
            default: the ``RAY_ADDRESS`` environment variable, else a new local instance.

    Raises:
        BackendError: an unknown name, an address for the local backend, the ray extra
            missing, or no cluster at the address.
    """
    if workers is not None and workers < 1:
        raise BackendError(f"--workers must be >= 1, got {workers}")
    if name == "local":
        if address:
            raise BackendError("--ray-address needs --backend ray")
        from agents.execution.local import LocalBackend

        return LocalBackend(workers)
    if name == "ray":
        from agents.execution.ray_backend import RayBackend

        return RayBackend(address=address or None, workers=workers)
    raise BackendError(f"backend {name!r}: use one of {', '.join(BACKENDS)}")


def add_backend_arguments(parser: argparse.ArgumentParser) -> None:
    """``--backend`` and ``--ray-address``, the same for every command that runs tasks."""
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="where tasks run: local (this machine's processes, the default) or "
                             "ray (a Ray cluster; needs the ray extra: pip install -e '.[ray]')")
    parser.add_argument("--ray-address", default=None, metavar="ADDRESS",
                        help="with --backend ray: the cluster to join, 'auto' (a cluster "
                             "started on this machine with `ray start --head`) or HOST:PORT; "
                             "default: $RAY_ADDRESS, else a Ray instance of its own on this "
                             "machine with --workers CPUs")


def backend_from_args(args: argparse.Namespace, workers: int | None = None) -> Backend:
    """The backend that ``--backend`` and ``--ray-address`` ask for (see :func:`make_backend`)."""
    return make_backend(args.backend, workers, args.ray_address)
