"""Typed configuration: the env config's schema (:mod:`~marl_vertiport.config.env`) and the
typed YAML loading every schema of the project uses (:mod:`~marl_vertiport.config.typed`).

``from marl_vertiport.config import load_config, EnvConfig, ConfigError`` is the public API;
docs/configs.md documents every key.
"""

from marl_vertiport.config.env import (
    CONFIG_DIR, MAX_COUNT, MAX_SUBSTEPS, MIN_STEP_M, PHYSICS_RATE_FLOOR_HZ, PHYSICS_RATE_MAX_HZ,
    ATCConfig, BatteryConfig, EnvConfig, FlightConfig, LayoutConfig, RewardConfig, SafetyConfig,
    ScheduleConfig, UncertaintyConfig, from_dict, load_config,
)
from marl_vertiport.config.rules import LATEST_RULES, RULES_VERSIONS, with_rules
from marl_vertiport.config.typed import (
    ConfigError, UnexpectedKeywordError, UnknownKeyError, build_dataclass, find_yaml,
    load_yaml_dataclass, read_yaml, resolve_path, set_dotted, to_dict,
)

__all__ = [
    "CONFIG_DIR", "LATEST_RULES", "MAX_COUNT", "RULES_VERSIONS", "MAX_SUBSTEPS", "MIN_STEP_M", "PHYSICS_RATE_FLOOR_HZ",
    "PHYSICS_RATE_MAX_HZ", "ATCConfig", "BatteryConfig", "ConfigError", "EnvConfig",
    "FlightConfig", "LayoutConfig", "RewardConfig", "SafetyConfig", "ScheduleConfig",
    "UncertaintyConfig", "UnexpectedKeywordError", "UnknownKeyError", "build_dataclass",
    "find_yaml", "from_dict", "load_config", "load_yaml_dataclass", "read_yaml", "resolve_path",
    "set_dotted", "to_dict", "with_rules",
]
