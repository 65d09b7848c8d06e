"""Typed YAML: frozen dataclasses as schemas, built from plain data with every key and type
checked, and the errors that name the field.

Every schema of the project loads through here: the env config
(:mod:`marl_vertiport.config.env`), train configs, evaluation suites, checks. A YAML file may
extend another with ``base: <name or path>``; an unknown key names the known ones; a dotted
override (``uncertainty.wind_gust_prob``) sets one field of a nested schema. A schema whose keys
or values were renamed gives a classmethod ``upgrade_data(data) -> data`` that reads the old
names as the new ones; it is called on the plain data before any check.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import Any

import yaml

__all__ = ["ConfigError", "UnexpectedKeywordError", "UnknownKeyError", "build_dataclass",
           "find_yaml", "load_yaml_dataclass", "read_yaml", "resolve_path", "set_dotted",
           "to_dict"]


class ConfigError(ValueError):
    """A config file or override that cannot describe a valid vertiport."""


class UnknownKeyError(ConfigError):
    """An override (``--set``, ``EnvConfig.replace``, a keyword) names no config key or
    section; the message lists the known ones. ``keyword`` is the override as it was given
    (``uncertainty__wind_gust_prob`` or ``uncertainty.wind_gust_prob``) where known."""

    keyword: str | None = None


class UnexpectedKeywordError(UnknownKeyError, TypeError):
    """An env constructor's keyword that is no config key: a :class:`ConfigError`, as the
    env's documentation promises, and a ``TypeError``, Python's and Gymnasium's convention
    for an unexpected keyword argument (wrappers such as TorchRL's ``GymEnv`` rely on it, and
    on its message starting as Python's own does)."""

    @classmethod
    def of(cls, owner: str, error: UnknownKeyError) -> "UnexpectedKeywordError":
        """The constructor error of ``owner`` (a class name) for an override ``error``."""
        new = cls(f"{owner}() got an unexpected keyword argument {error.keyword!r}: {error}")
        new.keyword = error.keyword
        return new


def _coerce(value: Any, tp: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true/false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{where}: must be a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if dataclasses.is_dataclass(tp):
        return _build(tp, value, where)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected a list of {len(args)} values, got {value!r}")
        return tuple(_coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if origin in (typing.Union, types.UnionType):
        raise ConfigError(f"{where}: unsupported union type")  # not used by the schema
    raise ConfigError(f"{where}: unsupported type {tp}")


def _build(cls: type, data: Any, where: str) -> Any:
    if isinstance(data, cls):
        return data
    if not isinstance(data, dict):
        raise ConfigError(f"{where or 'config'}: expected a mapping, got {data!r}")
    upgrade = getattr(cls, "upgrade_data", None)
    if upgrade is not None:
        data = upgrade(dict(data))
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted((k for k in data if k not in names), key=str)
    if unknown:
        prefix = f"{where}." if where else ""
        raise ConfigError(f"{prefix}{unknown[0]}: unknown key (known: {', '.join(sorted(names))})")
    missing = [f.name for f in dataclasses.fields(cls) if f.name not in data
               and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if missing:
        prefix = f"{where}." if where else ""
        raise ConfigError(f"{prefix}{missing[0]}: missing (it has no default)")
    kwargs = {}
    for key, value in data.items():
        kwargs[key] = _coerce(value, hints[key], f"{where}.{key}" if where else key)
    return cls(**kwargs)


def build_dataclass(cls: type, data: Any, where: str = "") -> Any:
    """Build any (nested) frozen dataclass schema from plain data with the same checks as the
    env config: unknown keys and wrong types fail with the field named."""
    return _build(cls, data, where)


def find_yaml(spec: str | Path, folder: Path, kind: str) -> Path:
    """The file ``spec`` names: a name in ``folder`` (without ``.yaml``) or a path. A missing
    one raises ``ConfigError`` naming ``kind`` and the shipped names."""
    path = Path(spec)
    if not path.suffix and not path.exists():
        path = folder / f"{spec}.yaml"
    if not path.is_file():
        known = ", ".join(sorted(p.relative_to(folder).with_suffix("").as_posix()
                                 for p in folder.rglob("*.yaml")))
        raise ConfigError(f"{kind} {str(spec)!r}: no such file (shipped: {known})")
    return path


def load_yaml_dataclass(cls: type, spec: str | Path, folder: Path, kind: str) -> Any:
    """A ``cls`` schema from a YAML file: ``spec`` is a name in ``folder`` (without ``.yaml``)
    or a path; the file may extend another with ``base: <path relative to it>``. A missing file (``kind`` names what was looked for, with the shipped names), bad
    YAML or a schema error raises ``ConfigError`` naming the file."""
    path = find_yaml(spec, folder, kind)
    data = read_yaml(path, folder)  # a ``base:`` key names a file it extends
    try:
        return build_dataclass(cls, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def to_dict(cfg: Any) -> dict[str, Any]:
    """Plain nested dict (lists for tuples) of a config, suitable for YAML."""

    def conv(v: Any) -> Any:
        if dataclasses.is_dataclass(v):
            return {f.name: conv(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, tuple):
            return [conv(x) for x in v]
        return v

    return conv(cfg)


def _known(node: dict[str, Any], sections: bool = False) -> str:
    """The keys of a config level, for an error message (only its sections if asked)."""
    keys = sorted(k for k, v in node.items() if not sections or isinstance(v, dict))
    return ", ".join(keys)


def set_dotted(data: dict[str, Any], key: str, value: Any, prefix: str = "") -> None:
    """Set ``key`` (dotted, below ``prefix``) of ``data`` to ``value``; a dict value sets the
    section's keys one by one. Errors name the full dotted key and list the known keys
    (:class:`UnknownKeyError`)."""
    if not isinstance(key, str):
        raise UnknownKeyError(f"{prefix}{key!r}: unknown key (keys are names; known: "
                              f"{_known(data)})")
    parts = key.split(".")
    node = data
    for i, part in enumerate(parts[:-1]):
        if part not in node or not isinstance(node[part], dict):
            where = f" in {prefix[:-1]}" if prefix else ""
            raise UnknownKeyError(f"{prefix}{'.'.join(parts[: i + 1])}: unknown config section"
                                  f"{where} (sections: {_known(node, sections=True)})")
        node = node[part]
    last = parts[-1]
    if isinstance(value, dict) and isinstance(node.get(last), dict):
        for sub_key, sub_value in value.items():
            set_dotted(node[last], sub_key, sub_value, f"{prefix}{key}.")
    elif last not in node:
        raise UnknownKeyError(f"{prefix}{key}: unknown key (known: {_known(node)})")
    else:
        node[last] = to_dict(value) if dataclasses.is_dataclass(value) else value


def _merge(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def read_yaml(path: Path, folder: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """Read a config file as plain data; a ``base: <name or path>`` key names a file it
    extends (a path relative to the file, or a name in ``folder``), whose keys it overrides
    section by section."""
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of config keys, got {type(data).__name__}")
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError(f"{path}: base: expected a config name or path, got {base!r}")
    base_path = resolve_path(base, folder, relative_to=path.parent)
    if base_path.resolve() in seen:
        raise ConfigError(f"{path}: base: {base!r} includes itself")
    return _merge(read_yaml(base_path, folder, seen + (path.resolve(),)), data)


def resolve_path(config: str | Path, folder: Path, relative_to: Path | None = None) -> Path:
    """The file ``config`` names: a path (relative to ``relative_to`` first, then to the working
    directory) or, without a suffix, a name in ``folder``."""
    path = Path(config)
    candidates = [path]
    if relative_to is not None and not path.is_absolute():
        candidates.insert(0, relative_to / path)
    if not path.suffix:
        candidates.append(folder / f"{config}.yaml")
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    known = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
    raise ConfigError(f"config {str(config)!r}: no such file (shipped configs: {known})")
