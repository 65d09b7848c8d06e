"""Controllers by name, import path or checkpoint: ``random``, ``fcfs``, ``dispatcher`` (the
expert rule), ``planner`` (a one-step look-ahead planner, which reads the simulator), ``guard``
(a proposer, the dispatcher by default, whose choices a look-ahead may veto to lose fewer
vehicles), ``gcn`` (the shipped trained policy, from the observation alone), ``lookahead``
(the learned ATC as shipped: a look-ahead search around a proposer, ``gcn`` by default),
``prior`` (a policy, ``gcn`` by default, with a rule, the dispatcher by default, as its prior:
:mod:`agents.controllers.prior`), ``package.module:Class`` or ``path/to/file.py:Class`` (a
class, or a ready object; modules and files resolve from the working directory, as under
``python -m``), the path of a training
checkpoint (``.pt``), or checkpoints joined by ``+`` (their ensemble,
:class:`agents.controllers.gcn.GCNEnsemble`), a policy trained in another library
(:mod:`agents.controllers.foreign`): a Stable-Baselines3 ``model.zip``, a ``torch.export``
``policy.pt2``, an RLlib checkpoint folder; or a controller object of this process, by the
name :func:`in_memory` gave it. The names before 0.2.0 (``heuristic``,
``rollout``, ``handback``) still work, with a note (:mod:`agents.common.names`).

A built-in name or an import path may carry constructor arguments in brackets, values read as
YAML: ``dispatcher[holding=false]``, ``planner[horizon=80,nominal=false]``,
``examples.custom_agent:ChargeFirst[low_battery_pct=40]``; an argument that names a controller
may carry brackets of its own: ``lookahead[rollout_policy=dispatcher[arrival_priority_pct=40]]``. The
whole spec (arguments included) names the controller in tables, so two settings of one
controller can be compared side by side.
Quote it in a shell (``'dispatcher[holding=false]'``): brackets are glob characters."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from agents.common.names import canonical_spec
from agents.common.specs import (  # noqa: F401 (re-exported: part of the registry's API)
    SHIPPED_CHECKPOINT, AgentSpecError, foreign_kind, split_spec,
)

#: Built-in controllers: name -> import path.
BUILTIN = {
    "random": "agents.controllers.random_agent:RandomController",
    "fcfs": "agents.controllers.fcfs:FCFSController",
    "dispatcher": "agents.controllers.dispatcher:DispatcherController",
    "planner": "agents.controllers.planner:PlannerController",
    "guard": "agents.controllers.guard:GuardController",
    "lookahead": "agents.controllers.lookahead:LookaheadController",
    "prior": "agents.controllers.prior:RulePriorController",
}

#: Library -> the class of :mod:`agents.controllers.foreign` that plays its files.
FOREIGN = {"sb3": "SB3Controller", "exported": "ExportedPolicyController", "rllib": "RLlibController"}
#: Controller objects of this process, by name (:func:`in_memory`).
_MEMORY: dict[str, Any] = {}


@contextlib.contextmanager
def in_memory(name: str, controller: Any) -> Iterator[str]:
    """Within the block, the spec ``name`` plays ``controller`` (an object with ``act``, not
    rebuilt: every episode in this process plays this object, after its ``reset``).

    Raises:
        AgentSpecError: ``name`` is already a spec (a built-in name, a path, brackets), or
            ``controller`` has no ``act``.
    """
    if (name in BUILTIN or name == "gcn" or not name or any(c in name for c in ":[]+/")
            or name.endswith((".pt", ".zip", ".pt2")) or name in _MEMORY):
        raise AgentSpecError(f"agent name {name!r} is taken, or reads as another spec; "
                             "choose a plain name such as 'mine'")
    if not callable(getattr(controller, "act", None)):
        raise AgentSpecError(f"agent {name!r}: {controller!r} has no act(observation) method")
    _MEMORY[name] = controller
    try:
        yield name
    finally:
        _MEMORY.pop(name, None)


def agent_help() -> str:
    """What an agent spec may be, for the ``--help`` of every command that takes one."""
    names = ", ".join([*BUILTIN, "gcn"])
    return (f"a built-in name ({names}; gcn is the shipped checkpoint, lookahead the learned "
            "ATC: a look-ahead search around it), the path of a training "
            "checkpoint (.pt), checkpoints joined by '+' (their ensemble), a policy of another "
            "library (an SB3 model.zip, a torch.export policy.pt2, an RLlib checkpoint "
            "folder; --trust to unpickle one that needs it), an import path "
            "'package.module:Class' or a file 'path/to/file.py:Class' (both from the working "
            "directory); constructor arguments "
            "in brackets, e.g. 'dispatcher[holding=false]'")


def _import(path: str, spec: str) -> Any:
    """The object ``path`` names: ``package.module:Attr`` or ``path/to/file.py:Attr`` (``Attr``
    may be dotted). Modules and files resolve from the working directory, as under
    ``python -m`` (:mod:`agents.common.imports`)."""
    from agents.common.imports import ImportTargetError, import_target

    try:
        return import_target(path)
    except ImportTargetError as exc:
        raise AgentSpecError(f"agent {spec!r}: {exc}") from exc.__cause__


def _checkpoint_path(spec: str) -> Path:
    """The file a checkpoint spec names: ``gcn`` is the shipped checkpoint, else a path."""
    return SHIPPED_CHECKPOINT if spec == "gcn" else Path(spec)


def make_controller(spec: str) -> Any:
    """Build the controller named by ``spec`` (a name from before 0.2.0 is read as its new
    name, with a note; a name :func:`in_memory` gave plays its object).

    Raises:
        AgentSpecError: unknown name, import failure, or an object without ``act``.
    """
    if spec in _MEMORY:
        return _MEMORY[spec]
    spec = canonical_spec(spec)
    if "+" in spec and all(p.endswith(".pt") or p == "gcn" for p in spec.split("+")):
        from agents.controllers.gcn import CheckpointError, GCNEnsemble

        try:  # checkpoints joined by "+": their ensemble
            return GCNEnsemble([_checkpoint_path(p) for p in spec.split("+")])
        except CheckpointError as exc:
            raise AgentSpecError(f"agent {spec!r}: {exc}") from exc
    target_spec, kwargs = split_spec(spec)
    if target_spec == "gcn" or target_spec.endswith(".pt"):
        from agents.controllers.gcn import CheckpointError, GCNController

        try:
            return GCNController(_checkpoint_path(target_spec), **kwargs)
        except CheckpointError as exc:
            raise AgentSpecError(f"agent {spec!r}: {exc}") from exc
        except TypeError as exc:  # an argument GCNController does not take
            raise AgentSpecError(f"agent {spec!r}: {exc}") from None
    kind = foreign_kind(target_spec)
    if kind is not None:
        from agents.controllers import foreign

        try:
            return getattr(foreign, FOREIGN[kind])(target_spec, **kwargs)
        except foreign.ForeignPolicyError as exc:
            raise AgentSpecError(f"agent {spec!r}: {exc}") from None
        except TypeError as exc:  # an argument the loader does not take
            raise AgentSpecError(f"agent {spec!r}: {exc}") from None
    if target_spec in BUILTIN:
        target = _import(BUILTIN[target_spec], spec)
    elif ":" in target_spec:
        target = _import(target_spec, spec)
    else:
        raise AgentSpecError(f"unknown agent {spec!r}: use {agent_help()}")
    if isinstance(target, type):
        try:
            controller = target(**kwargs)
        except TypeError as exc:  # a keyword the class does not take
            if kwargs:
                raise AgentSpecError(f"agent {spec!r}: {exc}") from None
            raise
    elif kwargs:
        raise AgentSpecError(f"agent {spec!r}: {target_spec!r} is an object, not a class; it "
                             "takes no arguments")
    else:
        controller = target
    if not callable(getattr(controller, "act", None)):
        raise AgentSpecError(f"agent {spec!r}: {controller!r} has no act(observation) method")
    if not hasattr(controller, "name"):
        try:
            controller.name = spec
        except AttributeError:
            pass
    return controller
