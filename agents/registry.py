"""Controllers by name or import path: ``random``, ``fcfs``, ``heuristic``, or
``package.module:Class`` (a class built with no arguments, or a ready object)."""

from __future__ import annotations

import importlib
from typing import Any

#: Built-in controllers: name -> import path.
BUILTIN = {
    "random": "agents.random_agent:RandomController",
    "fcfs": "agents.fcfs:FCFSController",
    "heuristic": "agents.heuristic:DispatcherController",
}


class AgentSpecError(ValueError):
    """An agent name or import path that does not give a controller."""


def _import(path: str, spec: str) -> Any:
    module_name, _, attr_path = path.partition(":")
    if not module_name or not attr_path:
        raise AgentSpecError(f"agent {spec!r}: an import path looks like 'package.module:Class'")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or an error raised while importing it
        raise AgentSpecError(f"agent {spec!r}: cannot import module {module_name!r}: "
                             f"{type(exc).__name__}: {exc}") from exc
    obj: Any = module
    for part in attr_path.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise AgentSpecError(f"agent {spec!r}: module {module_name!r} has no attribute "
                                 f"{attr_path!r}") from None
    return obj


def make_controller(spec: str) -> Any:
    """Build the controller named by ``spec``.

    Raises:
        AgentSpecError: unknown name, import failure, or an object without ``act``.
    """
    if spec in BUILTIN:
        target = _import(BUILTIN[spec], spec)
    elif ":" in spec:
        target = _import(spec, spec)
    else:
        raise AgentSpecError(f"unknown agent {spec!r}: use one of {sorted(BUILTIN)} or an import "
                             "path 'package.module:Class'")
    controller = target() if isinstance(target, type) else target
    if not callable(getattr(controller, "act", None)):
        raise AgentSpecError(f"agent {spec!r}: {controller!r} has no act(observation) method")
    if not hasattr(controller, "name"):
        try:
            controller.name = spec
        except AttributeError:
            pass
    return controller
