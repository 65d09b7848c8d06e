"""Controllers by name, import path or checkpoint: ``random``, ``fcfs``, ``heuristic``,
``rollout`` (the look-ahead planner, which reads the simulator), ``gcn``
(the shipped trained policy), ``package.module:Class`` (a class built with no arguments, or a
ready object), or the path of a training checkpoint (``.pt``)."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

#: The trained policy shipped with the repository (see agents/checkpoints/README.md).
SHIPPED_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "gcn_default.pt"

#: Built-in controllers: name -> import path.
BUILTIN = {
    "random": "agents.controllers.random_agent:RandomController",
    "fcfs": "agents.controllers.fcfs:FCFSController",
    "heuristic": "agents.controllers.dispatcher:DispatcherController",
    "rollout": "agents.controllers.planner:RolloutPlanner",
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
    if spec == "gcn" or spec.endswith(".pt"):
        from agents.gcn.policy import CheckpointError, GCNController

        path = SHIPPED_CHECKPOINT if spec == "gcn" else Path(spec)
        try:
            return GCNController(path)
        except CheckpointError as exc:
            raise AgentSpecError(f"agent {spec!r}: {exc}") from exc
    if spec in BUILTIN:
        target = _import(BUILTIN[spec], spec)
    elif ":" in spec:
        target = _import(spec, spec)
    else:
        raise AgentSpecError(f"unknown agent {spec!r}: use one of {sorted(BUILTIN) + ['gcn']}, an "
                             "import path 'package.module:Class' or a checkpoint path ending in .pt")
    controller = target() if isinstance(target, type) else target
    if not callable(getattr(controller, "act", None)):
        raise AgentSpecError(f"agent {spec!r}: {controller!r} has no act(observation) method")
    if not hasattr(controller, "name"):
        try:
            controller.name = spec
        except AttributeError:
            pass
    return controller
