"""Agent specs as text, the part every layer reads the same way: constructor arguments in
brackets (``dispatcher[holding=false]``), and the checkpoints a spec plays (``gcn``, a ``.pt``
path, checkpoints joined by ``+``). Building a controller from a spec is the registry's job
(:mod:`agents.controllers.registry`); the provenance of results reads the checkpoints here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agents.common.names import canonical_spec
from agents.common.spec_text import bracketed, top_level_items

__all__ = ["SHIPPED_CHECKPOINT", "AgentSpecError", "checkpoint_files", "split_spec"]

#: The trained policy shipped with the repository (see agents/checkpoints/README.md).
SHIPPED_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "gcn_default.pt"


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


#: Built-in controllers that play the checkpoint their ``proposer`` names, and their default
#: proposer (``None``: a rule, which plays none).
CHECKPOINT_PROPOSERS = {"lookahead": "gcn", "guard": None}


def checkpoint_files(spec: str) -> list[Path]:
    """The checkpoint files an agent spec plays (``gcn``, a ``.pt`` path, checkpoints joined
    by ``+``, or a look-ahead around one: ``lookahead``, ``guard[proposer=...]``); none for
    any other agent. Names from before 0.2.0 are read as their new names."""
    spec = canonical_spec(spec, note=False)
    try:
        target, kwargs = split_spec(spec)
    except AgentSpecError:
        target, kwargs = spec, {}
    if target in CHECKPOINT_PROPOSERS:
        proposer = kwargs.get("proposer", CHECKPOINT_PROPOSERS[target])
        return checkpoint_files(proposer) if isinstance(proposer, str) else []
    parts = spec.split("+") if "+" in spec else [target]
    files = []
    for part in parts:
        if part == "gcn":
            files.append(SHIPPED_CHECKPOINT)
        elif part.endswith(".pt"):
            files.append(Path(part))
        elif "+" in spec:
            return []
    return files
