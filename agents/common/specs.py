"""Agent specs as text, the part every layer reads the same way: constructor arguments in
brackets (``dispatcher[holding=false]``), and the checkpoints a spec plays (``gcn``, a ``.pt``
path, checkpoints joined by ``+``, a policy trained in another library: ``.zip``, ``.pt2``, an
RLlib checkpoint folder). Building a controller from a spec is the registry's job
(:mod:`agents.controllers.registry`); the provenance of results reads the checkpoints here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agents.common.names import canonical_spec
from agents.common.spec_text import bracketed, top_level_items

__all__ = ["SHIPPED_CHECKPOINT", "TRUST_VARIABLE", "AgentSpecError", "checkpoint_files",
           "foreign_kind", "rllib_module_state", "split_spec"]

#: The trained policy shipped with the repository (see agents/checkpoints/README.md).
SHIPPED_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "gcn_default.pt"


#: The environment variable that ``--trust`` sets (``1``): files of other libraries that only
#: load by unpickling may then be unpickled, which runs the code in them.
TRUST_VARIABLE = "MARL_VERTIPORT_TRUST_FILES"
#: What a policy file of another library is, by its name's ending.
FOREIGN_SUFFIXES = {".zip": "sb3", ".pt2": "exported"}
#: The file of an RLlib checkpoint that holds an RLModule's weights.
RLLIB_STATE = "module_state.pkl"


class AgentSpecError(ValueError):
    """An agent name or import path that does not give a controller."""


def split_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"dispatcher[holding=false,priority_margin_pct=3]"`` ->
    ``("dispatcher", {"holding": False, "priority_margin_pct": 3})``; a spec without brackets
    gives no arguments. A value may itself be a spec with arguments (it stays a string, for the
    controller to build): ``"lookahead[rollout_policy=dispatcher[arrival_priority_pct=40]]"``
    -> ``("lookahead", {"rollout_policy": "dispatcher[arrival_priority_pct=40]"})``.

    Raises:
        AgentSpecError: unbalanced brackets, an argument that is not ``key=value``, or a value
            that is not valid YAML.
    """
    import yaml

    if "[" not in spec and "]" not in spec:
        return spec, {}
    parts = bracketed(spec)
    if parts is None:
        raise AgentSpecError(f"agent {spec!r}: arguments look like 'name[key=value,key=value]'")
    target, args = parts
    kwargs: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in top_level_items(args))):
        key, sep, raw = item.partition("=")
        if not sep or not key.strip().isidentifier():
            raise AgentSpecError(f"agent {spec!r}: argument {item!r} is not key=value")
        try:
            kwargs[key.strip()] = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise AgentSpecError(f"agent {spec!r}: argument {item!r}: not valid YAML ({exc})") from None
    return target, kwargs


def foreign_kind(target: str) -> str | None:
    """Which library's policy ``target`` (a spec without its brackets) names: ``"sb3"`` (a
    ``.zip``), ``"exported"`` (a ``torch.export`` ``.pt2``), ``"rllib"`` (a folder, an RLlib
    checkpoint), or None (not a file of another library)."""
    if ":" in target or "+" in target:
        return None
    kind = FOREIGN_SUFFIXES.get(Path(target).suffix)
    if kind is None and ("/" in target or target.startswith(".")) and Path(target).is_dir():
        kind = "rllib"
    return kind


def rllib_module_state(folder: str | Path, module_id: str | None = None) -> Path:
    """The weights file (``module_state.pkl``) of the RLModule ``module_id`` in an RLlib
    checkpoint ``folder``: an algorithm's checkpoint (the learner's module is preferred), a
    multi-module's or one module's. Without ``module_id``, the checkpoint must hold one module.

    Raises:
        AgentSpecError: no such folder, no module's weights in it, or several and none chosen.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise AgentSpecError(f"{folder}: no such folder (an RLlib checkpoint is a folder)")
    found = sorted(folder.rglob(RLLIB_STATE), key=lambda f: ("learner" not in f.parts, str(f)))
    if module_id is not None:
        found = [f for f in found if f.parent.name == module_id]
    modules = sorted({f.parent.name for f in found})
    if not found:
        raise AgentSpecError(f"{folder}: no RLModule's {RLLIB_STATE} in it"
                             + (f" named {module_id!r}" if module_id else ""))
    if len(modules) > 1:
        raise AgentSpecError(f"{folder}: holds the modules {modules}; choose one with "
                             "[module=NAME]")
    return found[0]


#: Built-in controllers that play the checkpoint one of their arguments names: the argument and
#: its default (``None``: a rule, which plays none).
CHECKPOINT_PROPOSERS = {"lookahead": ("proposer", "gcn"), "guard": ("proposer", None),
                        "prior": ("policy", "gcn")}


def checkpoint_files(spec: str) -> list[Path]:
    """The checkpoint files an agent spec plays (``gcn``, a ``.pt`` path, checkpoints joined
    by ``+``, a look-ahead around one: ``lookahead``, ``guard[proposer=...]``, or one with a
    rule as its prior: ``prior[policy=...]``; a policy of
    another library: its ``.zip``, its ``.pt2``, its RLlib module's weights); none for any
    other agent. Names from before 0.2.0 are read as their new names."""
    spec = canonical_spec(spec, note=False)
    try:
        target, kwargs = split_spec(spec)
    except AgentSpecError:
        target, kwargs = spec, {}
    if target in CHECKPOINT_PROPOSERS:
        key, default = CHECKPOINT_PROPOSERS[target]
        proposer = kwargs.get(key, default)
        return checkpoint_files(proposer) if isinstance(proposer, str) else []
    parts = spec.split("+") if "+" in spec else [target]
    files = []
    for part in parts:
        if part == "gcn":
            files.append(SHIPPED_CHECKPOINT)
        elif part.endswith(".pt") or foreign_kind(part) in ("sb3", "exported"):
            files.append(Path(part))
        elif foreign_kind(part) == "rllib":
            try:
                files.append(rllib_module_state(part, kwargs.get("module")))
            except AgentSpecError:
                files.append(Path(part))
        elif "+" in spec:
            return []
    return files
