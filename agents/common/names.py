"""The controllers' names, and the names they had before 0.2.0.

Each built-in controller has one name, the same in the registry, the command line, the class
and the docs: ``dispatcher`` (:class:`~agents.controllers.dispatcher.DispatcherController`),
``planner``, ``guard``, ``lookahead``, and the unchanged ``random``, ``fcfs`` and ``gcn``.
Before 0.2.0 three of them had other names, and the look-ahead's arguments too; those still
work everywhere a name is read (agent specs, train configs, suites, sweeps, ``paired``'s
``--pair`` and ``--reference``, the result files made before), with a one-line note where a
person typed them (:class:`RenamedWarning`), and silently where a stored file holds them.

>>> canonical_spec("handback[fleet=heuristic[holding=false]]", note=False)
'lookahead[rollout_policy=dispatcher[holding=false]]'
"""

from __future__ import annotations

import warnings
from typing import Any

from agents.common.spec_text import bracketed, top_level_items

__all__ = ["RENAMED_AGENTS", "RENAMED_ARGUMENTS", "RENAMED_TEACHERS", "RenamedWarning",
           "canonical_agents", "canonical_kwargs", "canonical_spec", "note_renamed",
           "show_notes_on_one_line", "upgrade_agents"]

#: Agent names before 0.2.0 -> their names now.
RENAMED_AGENTS = {"heuristic": "dispatcher", "rollout": "planner", "handback": "lookahead"}

#: Per controller (its name now), arguments renamed in 0.2.0: old -> new. The look-ahead's
#: ``base`` is the controller whose choice it checks (its proposer), ``fleet`` the controller
#: that flies its rollouts; the planner's ``base`` is the controller it rolls out.
RENAMED_ARGUMENTS = {
    "guard": {"base": "proposer", "fleet": "rollout_policy"},
    "lookahead": {"base": "proposer", "fleet": "rollout_policy"},
    "planner": {"base": "rollout_policy"},
}

#: The warm start's teachers (``pretrain.teacher``) before 0.2.0 -> now.
RENAMED_TEACHERS = {"rollout": "planner", "guarded_rollout": "guarded_planner",
                    "heuristic": "dispatcher"}


class RenamedWarning(FutureWarning):
    """A name that changed in 0.2.0 was used; it still works. Shown once per name, on one line
    (the command line prints it as ``note: ...``)."""


_noted: set[str] = set()


def note_renamed(old: str, new: str, what: str) -> None:
    """Warn once per process that ``what`` ``old`` is now ``new`` (a :class:`RenamedWarning`)."""
    key = f"{what}:{old}"
    if key in _noted:
        return
    _noted.add(key)
    warnings.warn(f"{what} {old!r} is now {new!r} (the old name still works)", RenamedWarning,
                  stacklevel=3)


def show_notes_on_one_line() -> None:
    """Show every :class:`RenamedWarning` as one line, ``note: ...``, on stderr (the command
    line's form); any other warning as Python shows it."""
    import sys

    shown = warnings.showwarning
    if getattr(shown, "_one_line_notes", False):
        return

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, RenamedWarning):
            print(f"note: {message}", file=file or sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    show._one_line_notes = True  # type: ignore[attr-defined]
    warnings.showwarning = show


def canonical_kwargs(name: str, kwargs: dict[str, Any], note: bool = True,
                     spec: str | None = None) -> dict[str, Any]:
    """``kwargs`` of the controller ``name`` (its name now) with the arguments renamed in 0.2.0
    under their new names, and every value that is an agent spec under its new name.

    Raises:
        ValueError: an argument given under both its old and its new name."""
    renamed = RENAMED_ARGUMENTS.get(name, {})
    out: dict[str, Any] = {}
    for key, value in kwargs.items():
        new_key = renamed.get(key, key)
        if new_key != key:
            if new_key in kwargs:
                raise ValueError(f"agent {spec or name!r}: {key!r} is the old name of "
                                 f"{new_key!r}; give one of them")
            if note:
                note_renamed(key, new_key, f"{name} argument")
        if new_key in ("proposer", "rollout_policy") and isinstance(value, str):
            value = canonical_spec(value, note)
        out[new_key] = value
    return out


def canonical_spec(spec: str, note: bool = True) -> str:
    """``spec`` with every name that changed in 0.2.0 (the controller's, its arguments', the
    specs among its values) under its new name, the rest of its text as written; any other
    spec unchanged. ``note``: warn once per old name (:class:`RenamedWarning`); ``False`` for
    names read from stored files.

    Checkpoint paths, ensembles (``a.pt+b.pt``) and import paths come back as they are."""
    parts = bracketed(spec)
    name, args = parts if parts is not None else (spec.strip(), None)
    new = RENAMED_AGENTS.get(name, name)
    changed = new != name
    if changed and note:
        note_renamed(name, new, "agent")
    items = []
    for item in top_level_items(args) if args is not None else []:
        key, sep, raw = item.partition("=")
        key = key.strip()
        new_key = RENAMED_ARGUMENTS.get(new, {}).get(key, key) if sep else key
        if new_key != key and note:
            note_renamed(key, new_key, f"{new} argument")
        new_raw = canonical_spec(raw.strip(), note) if new_key in (
            "proposer", "rollout_policy") else raw
        if new_key != key or new_raw.strip() != raw.strip():
            changed = True
            item = f"{new_key}={new_raw}"
        items.append(item)
    if not changed:
        return spec
    return new if args is None else f"{new}[{','.join(items)}]"


def canonical_agents(specs: Any, note: bool = True) -> tuple[str, ...]:
    """Each spec of ``specs`` under its name now (:func:`canonical_spec`)."""
    return tuple(canonical_spec(str(s), note) for s in specs)


def upgrade_agents(_cls: type, data: dict) -> dict:
    """``upgrade_data`` of a typed config with an ``agents`` list (a suite, a train config's
    evaluation; :mod:`marl_vertiport.config.typed`): the agents under their names now, with a
    note for each old one."""
    if isinstance(data.get("agents"), (list, tuple)):
        data["agents"] = [canonical_spec(a) if isinstance(a, str) else a for a in data["agents"]]
    return data
