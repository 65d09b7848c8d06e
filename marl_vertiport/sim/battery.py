"""The paper's battery model (eq. 1 and section II-A), per step of ``minutes_per_step``:

* in the air, cruising (moved at least ``min_cruise_distance_m`` in the step):
  ``-cruise_drain_pct_per_m * cruise_drain_scale * s`` for the 3-D distance ``s`` flown
  (0.5 %/m times 0.25 under rules v1, times 1 under v0);
* in the air otherwise (hovering, holding, a short final bit of a leg): ``-hover_drain_pct``
  (2 %);
* idling on a normal port, or on a charging port whose charger failed this step:
  ``-ground_idle_drain_pct`` (4 %);
* on a working charging port: ``+charge_pct`` (10 %); with a taper
  (``charge_taper_start_pct`` below 100, off by default), above the taper's start the gain falls
  linearly to ``charge_taper_end_pct`` at 100 %, read at the level the step starts from;
* out of service: 0.

Levels are clipped to ``[0, 100]``. The status that counts is the one during the step (after the
action). docs/battery-and-uncertainty.md, section 8, and docs/energy.md (the taper); the energy a planned
flight needs is :mod:`marl_vertiport.sim.energy`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from marl_vertiport.config import BatteryConfig


class BatteryModel:
    """Battery change per step by status, distance flown and (with a taper) level.

    Args:
        battery: the config's battery section.
        airborne: per status code, whether a vehicle in it is in the air.
        on_port, on_charger: the status codes of a vehicle idling on a normal port and of one
            on a charging port.
    """

    def __init__(self, battery: BatteryConfig, airborne: Sequence[bool], on_port: int,
                 on_charger: int) -> None:
        self.cfg = battery
        rate = [-battery.hover_drain_pct if up else 0.0 for up in airborne]
        rate[on_port] = -battery.ground_idle_drain_pct
        rate[on_charger] = battery.charge_pct
        #: Change per step by status code, before the distance flown (or the level) is known.
        self.rate_pct = tuple(rate)
        #: Drain per metre flown when cruising.
        self.cruise_pct_per_m = battery.cruise_pct_per_m
        self.on_charger = on_charger
        #: Whether the charge per step depends on the level (``charge_taper_start_pct`` < 100).
        self.tapers = battery.charge_taper_start_pct < 100.0

    def charge_rate_pct(self, level_pct: float) -> float:
        """Charge per step on a working charging port for a battery at ``level_pct`` at the
        start of the step: ``charge_pct`` up to ``charge_taper_start_pct``, then falling
        linearly to ``charge_taper_end_pct`` at 100 %."""
        cfg = self.cfg
        start = cfg.charge_taper_start_pct
        if level_pct <= start:
            return cfg.charge_pct
        return cfg.charge_pct + (cfg.charge_taper_end_pct - cfg.charge_pct) * (
            (level_pct - start) / (100.0 - start))

    def changes(self, level: Sequence[float], status_during: Sequence[int],
                moved: Iterable[tuple[int, float]],
                failed_charging: Iterable[int] = ()) -> list[float]:
        """Per vehicle, the battery change (percent) of this step.

        Args:
            level: per vehicle, its battery (percent) at the start of the step, ``(N,)``; read
                only when the charge tapers.
            status_during: per vehicle, its status code during the step, ``(N,)``.
            moved: ``(vehicle, metres flown)`` of the vehicles that moved this step.
            failed_charging: vehicles on a charging port whose charger failed this step.
        """
        cfg = self.cfg
        rate, per_m = self.rate_pct, self.cruise_pct_per_m
        change = [rate[s] for s in status_during]
        if self.tapers:
            on_charger = self.on_charger
            for v, s in enumerate(status_during):
                if s == on_charger:
                    change[v] = self.charge_rate_pct(level[v])
        for v, dist in moved:
            if dist >= cfg.min_cruise_distance_m:
                change[v] = -per_m * dist
        for v in failed_charging:
            change[v] = -cfg.ground_idle_drain_pct
        return change

    @staticmethod
    def apply(level: list[float], change: Sequence[float]) -> list[float]:
        """New levels: ``level + change`` clipped to ``[0, 100]`` (``level`` is updated in place
        and returned)."""
        for v, c in enumerate(change):
            b = level[v] + c
            level[v] = 0.0 if b < 0.0 else 100.0 if b > 100.0 else b
        return level
