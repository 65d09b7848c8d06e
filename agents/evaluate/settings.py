"""What an evaluation runs and what it produces: the settings, one episode's task and
record, the evaluation, suites and ``--set`` overrides."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import yaml

from agents.common.names import canonical_agents, upgrade_agents
from agents.common.seeds import evaluation_seeds, seeds_rule
from agents.execution.base import INTERRUPTED  # noqa: F401 (the error of a run stopped with Ctrl-C)
from marl_vertiport.config import LATEST_RULES

DEFAULT_AGENTS = ("random", "fcfs", "dispatcher")
#: The paper's case 1 (no uncertainty) and case 2 (wind gusts, charger and take-off failures).
DEFAULT_CONFIGS = ("paper", "paper_uncertain")
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95
#: Episodes (from the first) whose action counts make the action-distribution chart.
ACTION_EPISODES = 5

Overrides = tuple[tuple[str, Any], ...]




class InputError(ValueError):
    """Bad command-line input (agent, config, override, episode count); nothing was run."""


SUITE_DIR = Path(__file__).resolve().parents[2] / "configs" / "suites"


@dataclass(frozen=True)
class SuiteConfig:
    """A named evaluation suite (``configs/suites/<name>.yaml``): which agents play which
    cases on which seeds."""

    name: str
    configs: tuple[str, ...]
    """Cases: env config names in configs/env/ or YAML paths."""
    agents: tuple[str, ...] = DEFAULT_AGENTS
    seeds: str = ""
    """``"START:STOP"`` (validation or test seeds); empty: ``EVAL_SEEDS[:episodes]``."""
    episodes: int = 50
    """Days per agent and case when ``seeds`` is not given."""

    #: Agents named as before 0.2.0 read as their names now, with a note.
    upgrade_data = classmethod(upgrade_agents)


def load_suite(spec: str | Path) -> SuiteConfig:
    """A suite by name (configs/suites/) or YAML path; errors name the file and the key."""
    from marl_vertiport.config import ConfigError, load_yaml_dataclass

    try:
        suite = load_yaml_dataclass(SuiteConfig, spec, SUITE_DIR, "suite")
    except ConfigError as exc:
        raise InputError(str(exc)) from None
    if not suite.configs or not suite.agents:
        raise InputError(f"suite {spec}: configs and agents must not be empty")
    return suite


# ============================================================================ settings, tasks


@dataclass(frozen=True)
class EvalSettings:
    """What to evaluate: agents x cases x the first ``episodes`` evaluation seeds."""

    agents: tuple[str, ...] = DEFAULT_AGENTS
    configs: tuple[str, ...] = DEFAULT_CONFIGS
    episodes: int = 50
    overrides: Overrides = ()
    bootstrap: int = BOOTSTRAP_RESAMPLES
    bootstrap_seed: int = BOOTSTRAP_SEED
    confidence: float = CONFIDENCE
    first_seed: int | None = None
    """Seeds ``first_seed .. first_seed + episodes - 1`` (``--seeds``) instead of
    ``EVAL_SEEDS[:episodes]``."""
    rules: int = LATEST_RULES
    """The env's rules version (``--rules``; ``vertiport_v{rules}``)."""

    def __post_init__(self) -> None:
        # Agents named as before 0.2.0 play, and are labelled, under their names now.
        object.__setattr__(self, "agents", canonical_agents(self.agents))

    @property
    def seeds(self) -> tuple[int, ...]:
        return evaluation_seeds(self.episodes, self.first_seed)

    @property
    def seeds_rule(self) -> str:
        """How the seeds were chosen, in words for the report and results.json."""
        return seeds_rule(self.episodes, self.first_seed, "--seeds")

    def tasks(self) -> list[EpisodeTask]:
        """Every episode to run, in (agent, case, episode) order."""
        return [EpisodeTask(agent, config, k, seed, self.overrides, self.rules)
                for agent in self.agents for config in self.configs
                for k, seed in enumerate(self.seeds)]

    def to_json(self) -> dict[str, Any]:
        return {"agents": list(self.agents), "configs": list(self.configs),
                "episodes": self.episodes, "seeds": list(self.seeds),
                "seeds_rule": self.seeds_rule,
                "overrides": {k: v for k, v in self.overrides}, "rules": self.rules,
                "bootstrap": {"resamples": self.bootstrap, "seed": self.bootstrap_seed,
                              "confidence": self.confidence, "method": "percentile"}}


@dataclass(frozen=True)
class EpisodeTask:
    """One episode: everything a worker process needs to run it."""

    agent: str
    config: str
    episode: int
    seed: int
    overrides: Overrides = ()
    rules: int = LATEST_RULES
    """The env's rules version (``vertiport_v{rules}``; results made before v1 replay with 0)."""


@dataclass
class EpisodeRecord:
    """The outcome of one episode: its metrics, or the error that stopped it."""

    task: EpisodeTask
    metrics: dict[str, Any] | None = None
    error: str | None = None
    seconds: float = 0.0


@dataclass
class Evaluation:
    """Everything an evaluation produced; ``error`` is set when it stopped early."""

    settings: EvalSettings
    records: list[EpisodeRecord]
    action_names: dict[str, list[str]]
    metrics: list[str] = field(default_factory=list)
    summary: list[dict[str, Any]] = field(default_factory=list)
    error: str | None = None
    seconds: float = 0.0
    provenance: dict[str, Any] = field(default_factory=dict)
    """The code, checkpoints and machine it was made with
    (:func:`agents.common.provenance.provenance`)."""

    @property
    def complete(self) -> bool:
        return self.error is None and len(self.records) == len(self.settings.tasks())

    def stat(self, agent: str, config: str, metric: str) -> dict[str, Any] | None:
        """The summary row of one (agent, case, metric), or None if it has no episode."""
        for row in self.summary:
            if (row["agent"], row["config"], row["metric"]) == (agent, config, metric):
                return row
        return None


def parse_overrides(items: Iterable[str]) -> Overrides:
    """``["schedule.episode_steps=60"]`` -> ``(("schedule.episode_steps", 60),)``; values are
    parsed with ``yaml.safe_load`` (numbers, booleans, lists)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--set {item!r}: expected KEY=VALUE, e.g. schedule.episode_steps=60")
        try:
            out[key.strip()] = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise InputError(f"--set {item!r}: the value is not valid YAML ({exc})") from None
    return tuple(out.items())


