"""Agent specs as text, the part every layer reads the same way: constructor arguments in
brackets (``heuristic[holding=false]``), and the checkpoints a spec plays (``gcn``, a ``.pt``
path, checkpoints joined by ``+``). Building a controller from a spec is the registry's job
(:mod:`agents.controllers.registry`); the provenance of results reads the checkpoints here.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

__all__ = ["SHIPPED_CHECKPOINT", "AgentSpecError", "checkpoint_files", "split_spec"]

#: The trained policy shipped with the repository (see agents/checkpoints/README.md).
SHIPPED_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "gcn_default.pt"


class AgentSpecError(ValueError):
    """An agent name or import path that does not give a controller."""


_ARGS = re.compile(r"^(?P<target>[^\[\]]+)\[(?P<args>[^\[\]]*)\]$")


def split_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"heuristic[holding=false,priority_margin_pct=3]"`` ->
    ``("heuristic", {"holding": False, "priority_margin_pct": 3})``; a spec without brackets
    gives no arguments.

    Raises:
        AgentSpecError: unbalanced brackets, an argument that is not ``key=value``, or a value
            that is not valid YAML.
    """
    import yaml

    if "[" not in spec and "]" not in spec:
        return spec, {}
    match = _ARGS.match(spec)
    if match is None:
        raise AgentSpecError(f"agent {spec!r}: arguments look like 'name[key=value,key=value]'")
    kwargs: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in match["args"].split(","))):
        key, sep, raw = item.partition("=")
        if not sep or not key.strip().isidentifier():
            raise AgentSpecError(f"agent {spec!r}: argument {item!r} is not key=value")
        try:
            kwargs[key.strip()] = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise AgentSpecError(f"agent {spec!r}: argument {item!r}: not valid YAML ({exc})") from None
    return match["target"].strip(), kwargs


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
