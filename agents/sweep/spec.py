"""What a sweep runs: a YAML file (``configs/sweeps/<name>.yaml``) naming agents, cases, a grid
of config overrides and the evaluation days; its grid points and its episode tasks.

A sweep file::

    agents: [fcfs, dispatcher]         # as for agents.evaluate
    configs: [paper]                   # env configs (names or YAML paths)
    grid:                              # every combination of these values is a point
      uncertainty.wind_gust_prob: [0.0, 0.05, 0.1, 0.2]
    set:                               # overrides for every point (optional)
      schedule.episode_steps: 1440
    episodes: 20                       # the first 20 evaluation seeds, or:
    seeds: "1000000:1000020"           # a seed range (validation or test seeds)
    metrics: [total_reward, stranded]  # the figure's panels (optional)

Every point plays the same days, so the points differ only by the swept values.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.common.names import canonical_agents
from agents.common.seeds import EVAL_SEEDS, evaluation_seeds, parse_seed_range, seeds_rule
from agents.evaluate.settings import EpisodeTask, InputError, Overrides
from marl_vertiport.config import ConfigError, find_yaml

SWEEP_DIR = Path(__file__).resolve().parents[2] / "configs" / "sweeps"
#: The figure's panels unless the file names others: reward and safety side by side.
DEFAULT_METRICS = ("total_reward", "stranded", "collisions", "separation_losses",
                   "mean_delay_min", "completed_trips")
_KEYS = ("agents", "configs", "grid", "set", "episodes", "seeds", "metrics")


@dataclass(frozen=True)
class SweepSpec:
    """A sweep: ``agents`` x ``configs`` x grid points x seeds, one episode each."""

    name: str
    agents: tuple[str, ...]
    configs: tuple[str, ...]
    grid: tuple[tuple[str, tuple[Any, ...]], ...]
    """Swept keys (dotted config keys) and their values, in file order."""
    fixed: Overrides = ()
    """Overrides of every point (the file's ``set``)."""
    episodes: int = 20
    first_seed: int | None = None
    """Seeds ``first_seed ..`` instead of ``EVAL_SEEDS[:episodes]``."""
    metrics: tuple[str, ...] = DEFAULT_METRICS

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(k for k, _ in self.grid)

    @property
    def seeds(self) -> tuple[int, ...]:
        return evaluation_seeds(self.episodes, self.first_seed)

    @property
    def seeds_rule(self) -> str:
        return seeds_rule(self.episodes, self.first_seed)

    def points(self) -> list[Overrides]:
        """Every combination of the grid's values, the first key varying slowest."""
        values = [v for _, v in self.grid]
        return [tuple(zip(self.keys, combo)) for combo in itertools.product(*values)]

    def tasks(self) -> list[EpisodeTask]:
        """Every episode, in (agent, case, point, episode) order; a task's overrides are the
        fixed ones followed by its point's."""
        return [EpisodeTask(agent, config, k, seed, self.fixed + point)
                for agent in self.agents for config in self.configs
                for point in self.points() for k, seed in enumerate(self.seeds)]

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "agents": list(self.agents), "configs": list(self.configs),
                "grid": {k: list(v) for k, v in self.grid}, "set": dict(self.fixed),
                "episodes": self.episodes, "seeds": list(self.seeds),
                "seeds_rule": self.seeds_rule, "metrics": list(self.metrics)}


def point_label(point: Overrides) -> str:
    """``uncertainty.wind_gust_prob=0.1, ...`` for messages and the progress bar."""
    return ", ".join(f"{k}={v}" for k, v in point)


def _strings(value: Any, key: str, where: str) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise InputError(f"{where}: {key}: expected a non-empty list of names, got {value!r}")
    return tuple(dict.fromkeys(value))


def _scalar(value: Any) -> bool:
    return isinstance(value, (bool, int, float, str))


def parse_grid(data: Any, where: str) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    """The ``grid`` mapping: dotted keys to non-empty lists of distinct scalar values."""
    if not isinstance(data, dict) or not data:
        raise InputError(f"{where}: grid: expected a mapping of config keys to lists of values, "
                         f"e.g. uncertainty.wind_gust_prob: [0, 0.1, 0.2]; got {data!r}")
    grid = []
    for key, values in data.items():
        if not isinstance(key, str) or not key.strip():
            raise InputError(f"{where}: grid: {key!r} is not a config key")
        if not isinstance(values, list):
            values = [values]
        if not values or not all(_scalar(v) for v in values):
            raise InputError(f"{where}: grid.{key}: expected a non-empty list of numbers, "
                             f"booleans or strings, got {values!r}")
        if len(set(map(repr, values))) != len(values):
            raise InputError(f"{where}: grid.{key}: a value is listed twice: {values!r}")
        grid.append((key, tuple(values)))
    return tuple(grid)


def parse_sweep(data: Any, name: str, where: str) -> SweepSpec:
    """A :class:`SweepSpec` from a sweep file's plain data; errors name ``where`` and the key.
    Does not check that agents and configs exist (:func:`agents.sweep.cli.validate` does)."""
    from marl_vertiport.sim.metrics import METRICS

    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a mapping with {', '.join(_KEYS)}")
    unknown = sorted(str(k) for k in data if k not in _KEYS)
    if unknown:
        raise InputError(f"{where}: {unknown[0]}: unknown key (known: {', '.join(_KEYS)})")
    if "agents" not in data:
        raise InputError(f"{where}: agents: missing (the controllers to compare)")
    agents = canonical_agents(_strings(data["agents"], "agents", where))  # names before 0.2.0
    configs = _strings(data.get("configs", ["paper"]), "configs", where)
    grid = parse_grid(data.get("grid"), where)
    fixed = data.get("set") or {}
    if not isinstance(fixed, dict):
        raise InputError(f"{where}: set: expected a mapping of config keys to values")
    clash = sorted(set(fixed) & {k for k, _ in grid})
    if clash:
        raise InputError(f"{where}: {clash[0]} is both swept (grid) and fixed (set)")
    episodes, first_seed = data.get("episodes"), None
    if data.get("seeds"):
        try:
            seeds = parse_seed_range(str(data["seeds"]))
        except ValueError as exc:
            raise InputError(f"{where}: seeds: {exc}") from None
        if episodes is not None and episodes != len(seeds):
            raise InputError(f"{where}: episodes {episodes} and seeds {data['seeds']} "
                             f"({len(seeds)} seeds) disagree; give one of them")
        episodes, first_seed = len(seeds), seeds.start
    episodes = 20 if episodes is None else episodes
    if isinstance(episodes, bool) or not isinstance(episodes, int) or not (
            first_seed is not None or 1 <= episodes <= len(EVAL_SEEDS)):
        raise InputError(f"{where}: episodes: expected an integer from 1 to {len(EVAL_SEEDS)}, "
                         f"got {episodes!r}")
    metrics = _strings(data.get("metrics", list(DEFAULT_METRICS)), "metrics", where)
    bad = [m for m in metrics if m not in METRICS]
    if bad:
        raise InputError(f"{where}: metrics: {bad[0]!r} is not a metric "
                         f"(known: {', '.join(METRICS)})")
    return SweepSpec(name, agents, configs, grid, tuple(fixed.items()), episodes, first_seed,
                     metrics)


def load_sweep(spec: str | Path, changes: dict[str, Any] | None = None) -> SweepSpec:
    """A sweep by name (``configs/sweeps/``) or YAML path, with ``changes`` from the command
    line applied first: top-level keys replace the file's, except ``grid`` and ``set``, whose
    entries are added to (or replace) the file's."""
    try:
        path = find_yaml(spec, SWEEP_DIR, "sweep")
    except ConfigError as exc:
        raise InputError(str(exc)) from None
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML: {exc}") from None
    if changes and isinstance(data, dict):
        data = dict(data)
        for key, value in changes.items():
            if key in ("grid", "set"):
                old = data.get(key) if isinstance(data.get(key), dict) else {}
                data[key] = {**old, **value}
            else:
                data[key] = value
        if "seeds" in changes and "episodes" not in changes:
            data.pop("episodes", None)  # --seeds decides the count
        if "episodes" in changes and "seeds" not in changes:
            data.pop("seeds", None)
    return parse_sweep(data, path.stem, str(path))
