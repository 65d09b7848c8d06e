"""The Gymnasium ids ``marl_vertiport/Vertiport-v1`` (the latest rules) and ``-v0``, registered without importing Gymnasium
before it is needed.

``import marl_vertiport`` (and so ``import marl_vertiport.sim``) loads no RL library. The id is
registered as soon as Gymnasium is loaded: at once when it already is, else by a one-shot hook
on Gymnasium's import (Gymnasium 1.x has no plugin entry points). Either way
``gymnasium.make("marl_vertiport/Vertiport-v0")`` works after ``import marl_vertiport``, in any
order of the two imports; ``gymnasium.make("marl_vertiport:marl_vertiport/Vertiport-v0")``
works with no import of ours at all (Gymnasium imports the module named before the colon).
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
from typing import Any

__all__ = ["ENV_ID", "ENV_IDS", "register", "register_when_gymnasium_loads"]

#: The latest version's id.
ENV_ID = "marl_vertiport/Vertiport-v1"
#: Every version's id and its env class; ``VertiportFlat-v1`` is the latest version with the
#: flat ``Box`` observation (:mod:`marl_vertiport.flat`).
ENV_IDS = {"marl_vertiport/Vertiport-v1": "marl_vertiport.gym_env:VertiportEnv",
           "marl_vertiport/Vertiport-v0": "marl_vertiport.gym_env:VertiportEnvV0",
           "marl_vertiport/VertiportFlat-v1": "marl_vertiport.flat:make_flat_env"}


def register() -> None:
    """Register the single-agent env under every id of :data:`ENV_IDS` (once). No order-enforcing or checker
    wrappers: Gymnasium's wrappers do not forward the env's own methods (``state()``,
    ``action_masks()``), and the env enforces the order itself."""
    import gymnasium

    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point, order_enforce=False,
                               disable_env_checker=True)


class _Loader(importlib.abc.Loader):
    """Gymnasium's own loader, then :func:`register`."""

    def __init__(self, inner: importlib.abc.Loader) -> None:
        self.inner = inner

    def create_module(self, spec: Any) -> Any:
        return self.inner.create_module(spec)

    def exec_module(self, module: Any) -> None:
        self.inner.exec_module(module)
        register()

    def __getattr__(self, name: str) -> Any:  # resources and the like: Gymnasium's loader's
        return getattr(self.inner, name)


class _OnGymnasiumImport(importlib.abc.MetaPathFinder):
    """Finds nothing itself: when ``gymnasium`` is first imported it hands Python the real
    spec with :class:`_Loader` around its loader, and removes itself."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "gymnasium":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            spec.loader = _Loader(spec.loader)
        return spec


def register_when_gymnasium_loads() -> None:
    """Register now if Gymnasium is loaded, else as soon as it is."""
    if "gymnasium" in sys.modules:
        register()
    elif not any(isinstance(f, _OnGymnasiumImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _OnGymnasiumImport())
