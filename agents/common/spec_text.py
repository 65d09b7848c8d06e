"""The text of an agent spec, split without reading its values: ``name[key=value,...]``, where a
value may be a spec with brackets of its own. The primitives :mod:`agents.common.specs` (which
reads the values as YAML) and :mod:`agents.common.names` (which renames names in the text) share.
"""

from __future__ import annotations

__all__ = ["bracketed", "top_level_items"]


def bracketed(spec: str) -> tuple[str, str] | None:
    """``"name[args]"`` -> ``("name", "args")``, where ``args`` may hold balanced brackets of its
    own (a spec as a value: ``lookahead[rollout_policy=dispatcher[holding=false]]``); ``None``
    where the spec is not of that form (no name, unbalanced brackets, text after the closing
    one)."""
    start = spec.find("[")
    if start < 0 or not spec[:start].strip() or "]" in spec[:start] or not spec.endswith("]"):
        return None
    depth = 0
    for i in range(start, len(spec)):
        depth += {"[": 1, "]": -1}.get(spec[i], 0)
        if depth == 0 and i < len(spec) - 1:
            return None  # the name's brackets close before the end
    return (spec[:start].strip(), spec[start + 1:-1]) if depth == 0 else None


def top_level_items(args: str) -> list[str]:
    """``args`` split at the commas outside brackets: ``"a=1,f=x[b=2,c=3]"`` ->
    ``["a=1", "f=x[b=2,c=3]"]``."""
    items, depth, start = [], 0, 0
    for i, char in enumerate(args):
        depth += {"[": 1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            items.append(args[start:i])
            start = i + 1
    return [*items, args[start:]]
