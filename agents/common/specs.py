"""Agent specs as text, the part every layer reads the same way: constructor arguments in
brackets (``heuristic[holding=false]``), and the checkpoints a spec plays (``gcn``, a ``.pt``
path, checkpoints joined by ``+``). Building a controller from a spec is the registry's job
(:mod:`agents.controllers.registry`); the provenance of results reads the checkpoints here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["SHIPPED_CHECKPOINT", "AgentSpecError", "checkpoint_files", "split_spec"]

#: The trained policy shipped with the repository (see agents/checkpoints/README.md).
SHIPPED_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "gcn_default.pt"


class AgentSpecError(ValueError):
    """An agent name or import path that does not give a controller."""


def _bracketed(spec: str) -> tuple[str, str] | None:
    """``"name[args]"`` -> ``("name", "args")``, where ``args`` may hold balanced brackets of its
    own (a spec as a value: ``handback[fleet=heuristic[holding=false]]``); ``None`` where the
    spec is not of that form (no name, unbalanced brackets, text after the closing one)."""
    start = spec.find("[")
    if start < 0 or not spec[:start].strip() or "]" in spec[:start] or not spec.endswith("]"):
        return None
    depth = 0
    for i in range(start, len(spec)):
        depth += {"[": 1, "]": -1}.get(spec[i], 0)
        if depth == 0 and i < len(spec) - 1:
            return None  # the name's brackets close before the end
    return (spec[:start].strip(), spec[start + 1:-1]) if depth == 0 else None


def _top_level_items(args: str) -> list[str]:
    """``args`` split at the commas outside brackets: ``"a=1,f=x[b=2,c=3]"`` ->
    ``["a=1", "f=x[b=2,c=3]"]``."""
    items, depth, start = [], 0, 0
    for i, char in enumerate(args):
        depth += {"[": 1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            items.append(args[start:i])
            start = i + 1
    return [*items, args[start:]]


def split_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"heuristic[holding=false,priority_margin_pct=3]"`` ->
    ``("heuristic", {"holding": False, "priority_margin_pct": 3})``; a spec without brackets
    gives no arguments. A value may itself be a spec with arguments (it stays a string, for the
    controller to build): ``"handback[fleet=heuristic[arrival_priority_pct=40]]"`` ->
    ``("handback", {"fleet": "heuristic[arrival_priority_pct=40]"})``.

    Raises:
        AgentSpecError: unbalanced brackets, an argument that is not ``key=value``, or a value
            that is not valid YAML.
    """
    import yaml

    if "[" not in spec and "]" not in spec:
        return spec, {}
    parts = _bracketed(spec)
    if parts is None:
        raise AgentSpecError(f"agent {spec!r}: arguments look like 'name[key=value,key=value]'")
    target, args = parts
    kwargs: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in _top_level_items(args))):
        key, sep, raw = item.partition("=")
        if not sep or not key.strip().isidentifier():
            raise AgentSpecError(f"agent {spec!r}: argument {item!r} is not key=value")
        try:
            kwargs[key.strip()] = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise AgentSpecError(f"agent {spec!r}: argument {item!r}: not valid YAML ({exc})") from None
    return target, kwargs


#: Built-in controllers that play the checkpoint their ``base`` names, and their default base
#: (``None``: a rule, which plays none).
CHECKPOINT_BASES = {"handback": "gcn", "guard": None}


def checkpoint_files(spec: str) -> list[Path]:
    """The checkpoint files an agent spec plays (``gcn``, a ``.pt`` path, checkpoints joined
    by ``+``, or a look-ahead around one: ``handback``, ``guard[base=...]``); none for any
    other agent."""
    try:
        target, kwargs = split_spec(spec)
    except AgentSpecError:
        target, kwargs = spec, {}
    if target in CHECKPOINT_BASES:
        base = kwargs.get("base", CHECKPOINT_BASES[target])
        return checkpoint_files(base) if isinstance(base, str) else []
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
