"""The env's rules versions, as PettingZoo versions its envs: a change of behaviour is a new
version, and the old one keeps its behaviour bit for bit (CHANGELOG.md, "Rules versions", lists
every version and every change made to v1 after it was first published, the energy calibration
among them).

- **v1** (``vertiport_v1``, ``marl_vertiport/Vertiport-v1``; the schema's defaults): the ATC's
  separation check and the airspace procedures of :mod:`marl_vertiport.sim.clearance`
  (``atc.separation_check``, departures at ``flight.departure_altitude_m``, arrivals at
  ``flight.arrival_altitude_m``, holding slots) and the energy of an operation calibrated to
  the paper's code (``battery.cruise_drain_scale``).
- **v0** (``vertiport_v0``, ``marl_vertiport/Vertiport-v0``): the rules before them: no
  separation check, departures and arrivals at the transit altitude, the paper's drain per metre
  unscaled. :func:`with_rules` sets those four keys whatever the config says; every other key is
  the config's.
"""

from __future__ import annotations

from marl_vertiport.config.env import EnvConfig
from marl_vertiport.config.typed import ConfigError

#: The rules versions there are; the last is the default.
RULES_VERSIONS = (0, 1)
LATEST_RULES = RULES_VERSIONS[-1]


def with_rules(cfg: EnvConfig, rules: int) -> EnvConfig:
    """``cfg`` under the rules of version ``rules`` (v1: as it is; v0: no separation check,
    departures and arrivals at the transit altitude, ``battery.cruise_drain_scale`` 1)."""
    if rules == 1:
        return cfg
    if rules == 0:
        transit = cfg.flight.transit_altitude_m
        if not cfg.atc.separation_check and cfg.flight.arrival_altitude_m == transit \
                and cfg.flight.departure_altitude_m == transit \
                and cfg.battery.cruise_drain_scale == 1.0:
            return cfg
        return cfg.replace(**{"atc.separation_check": False,
                              "flight.departure_altitude_m": transit,
                              "flight.arrival_altitude_m": transit,
                              "battery.cruise_drain_scale": 1.0})
    raise ConfigError(f"rules: version {rules!r} does not exist; known: {list(RULES_VERSIONS)}")
