"""Objects named on a command line: ``package.module:Attr`` or ``path/to/file.py:Attr``.

Both forms resolve from the working directory, the way ``python -m`` resolves a module: the
working directory goes on the import path (first, where it is not already on it), and a file
path is read relative to it. So ``marl-vertiport evaluate --agents mine:Ctrl``, ``make evaluate
AGENTS=mine:Ctrl`` and ``python -m agents.evaluate --agents mine:Ctrl`` find the same class, and
so does every worker process, which starts in the same folder. ``Attr`` may be dotted
(``module:Outer.Inner``).

A file is imported as a module of its own, under a name made from its resolved path, so loading
it twice gives the same module and its classes can be dataclasses or pickled by name within one
process.
"""

from __future__ import annotations

import difflib
import hashlib
import importlib
import importlib.util
import os
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["ImportTargetError", "import_target", "is_file_target", "target_file"]

#: How a target looks, for error messages.
FORMS = "'package.module:Class' or 'path/to/file.py:Class'"


class ImportTargetError(ValueError):
    """A target that does not name an object: malformed, a module or file that cannot be
    imported, or an attribute it does not have (the message says which, and what is there)."""


def is_file_target(source: str) -> bool:
    """Whether the part before ``:`` names a file (ends in ``.py`` or holds a path separator)
    rather than a module."""
    return source.endswith(".py") or "/" in source or os.sep in source


def import_target(target: str) -> Any:
    """The object ``target`` names.

    Raises:
        ImportTargetError: malformed target, a module or file that does not import (its
            error named), or a missing attribute (with the closest names the module has).
    """
    source, sep, attr_path = target.rpartition(":")
    if not sep or not source or not attr_path:
        raise ImportTargetError(f"an import path looks like {FORMS}, got {target!r}")
    if is_file_target(source):
        module, where = _import_file(source), f"file {source!r}"
    else:
        module, where = _import_module(source), f"module {source!r}"
    obj: Any = module
    for depth, part in enumerate(attr_path.split(".")):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            owner = where if depth == 0 else f"{where}: {'.'.join(attr_path.split('.')[:depth])}"
            raise ImportTargetError(f"{owner} has no attribute {part!r}{_suggest(part, obj)}") from None
    return obj


def target_file(target: str) -> Path | None:
    """The source file of the module or file ``target`` (``module:Attr`` or ``file.py:Attr``)
    names, resolved from the working directory as :func:`import_target` resolves it, without
    importing it; ``None`` where there is none (a built-in module, no such module or file)."""
    source, sep, _ = target.rpartition(":")
    if not sep or not source:
        return None
    if is_file_target(source):
        path = Path(source).expanduser()
        path = path if path.is_absolute() else Path(os.getcwd()) / path
        return path.resolve() if path.is_file() else None
    _working_directory_on_path()
    try:
        spec = importlib.util.find_spec(source)
    except (ImportError, ValueError):
        return None
    origin = getattr(spec, "origin", None)
    return Path(origin).resolve() if origin and Path(origin).is_file() else None


def _suggest(name: str, obj: Any) -> str:
    """``; did you mean 'A'?`` from the public names of ``obj``, else the first of them."""
    names = sorted(n for n in dir(obj) if not n.startswith("_"))
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.6)
    if close:
        return f"; did you mean {' or '.join(repr(n) for n in close)}?"
    if names:
        shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
        return f" (it has: {shown})"
    return ""


def _working_directory_on_path() -> str:
    """Put the working directory first on ``sys.path`` unless it is there already (``''`` and
    ``'.'`` count as it); return it."""
    cwd = os.getcwd()
    if cwd not in {os.path.abspath(p or os.curdir) for p in sys.path}:
        sys.path.insert(0, cwd)
    return cwd


def _import_module(name: str) -> ModuleType:
    cwd = _working_directory_on_path()
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name and (name == exc.name or name.startswith(exc.name + ".")):
            raise ImportTargetError(
                f"cannot import module {name!r}: no module named {exc.name!r} in the working "
                f"directory ({cwd}) or the installed packages") from exc
        raise ImportTargetError(f"cannot import module {name!r}: "
                                f"{type(exc).__name__}: {exc}") from exc
    except Exception as exc:  # an error raised by the module's own code while it imports
        raise ImportTargetError(f"cannot import module {name!r}: "
                                f"{type(exc).__name__}: {exc}") from exc


def _import_file(source: str) -> ModuleType:
    cwd = _working_directory_on_path()
    path = Path(source).expanduser()
    if not path.is_absolute():
        path = Path(cwd) / path
    if not path.is_file():
        raise ImportTargetError(f"cannot import file {source!r}: no such file (looked from the "
                                f"working directory {cwd})")
    path = path.resolve()
    stem = re.sub(r"\W", "_", path.stem)
    name = f"_marl_vertiport_file_{stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:10]}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportTargetError(f"cannot import file {source!r}: not a Python source file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # before it runs: dataclasses look their module up
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[name]
        raise ImportTargetError(f"cannot import file {source!r}: "
                                f"{type(exc).__name__}: {exc}") from exc
    return module
