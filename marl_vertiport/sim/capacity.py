"""Whether a vertiport can carry its fleet, derived from the config alone (no simulated day).

A vehicle's cycle is a trip (take-off, out to its destination, back, onto a hover spot, down on a
charging port), a wait on the charging port until it has the trip's energy back and its turn
comes, and the waits for its turns in between. Per cycle, with the mean over ports and
destinations of the planned trip (:class:`~marl_vertiport.sim.energy.FlightEnergy`, no gusts):

* ``turn_gap_min``: minutes between two turns of a vehicle. The paper's rule gives every
  vehicle a turn in order: ``N`` steps, ``N`` minutes at one step a minute and half that where
  the ATC decides twice a minute (``schedule.minutes_per_step``). With
  ``atc.skip_agents_without_decision`` the vehicles away are passed over: ``N`` times the share
  of a cycle a vehicle spends at the vertiport. The battery's rates are per step; the model
  works in minutes.
* ``energy_pct``: the trip's energy plus half a turn gap of hovering on return, the mean wait
  for the turn that lands it.
* ``charger_min``: a charging port's minutes per cycle: the vehicle's time on the ground, the
  flight plan's turnaround (the mean of ``schedule.takeoff_after_landing_min``), or longer where
  charging the cycle's energy at ``charge_pct`` a minute (less the chargers' failure rate) or a
  turn gap takes longer.
* ``cycle_min``: the trip's minutes, the time on the ground, and half a turn gap.
* ``utilisation``: ground minutes the fleet spends a minute over the charging ports there are,
  ``N x charger_min / cycle_min / chargers``: above 1, some vehicles wait on normal ports.
* ``hover_wait_pct``, ``idle_wait_pct``: the battery a vehicle spends waiting one whole turn
  gap, hovering (2 %/min in the paper) or idling on a normal port (4 %/min).

Verdict: **overloaded** when a trip, a whole turn gap of hovering and the reserve exceed a full
battery (a vehicle that returns and waits for its turn runs empty), or when the charging ports
are busy more than 80 % of the time (vehicles queue for them and land on normal ports) and a
vehicle back from a trip that idles a turn gap on a normal port no longer holds the next trip and
the reserve; **marginal** when normal ports are such a trap without the queue, or when the
charging ports are busy all the time (utilisation above 1); **carried** otherwise. The model
counts energy, charging ports and turns, not the holds of the separation check. Its thresholds
are rules of thumb of queueing (a server busy more than 80 % of the time has long queues) and of
the battery, not fitted to simulated days; ``tests/sim/test_capacity_model.py`` checks
the verdicts against days of the dispatcher.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from marl_vertiport.config import EnvConfig
from marl_vertiport.sim.energy import FlightEnergy
from marl_vertiport.sim.layout import Layout

#: Utilisation of the charging ports above which a queue builds up.
MARGINAL_UTILISATION = 0.8


@dataclass(frozen=True)
class Capacity:
    """A vertiport's capacity (see the module docstring for each quantity)."""

    name: str
    fleet_size: int
    chargers: int
    normal_ports: int
    turn_gap_min: float
    trip_min: float
    trip_pct: float
    energy_pct: float
    charger_min: float
    cycle_min: float
    utilisation: float
    hover_wait_pct: float
    idle_wait_pct: float
    verdict: str
    reason: str


def capacity(cfg: EnvConfig) -> Capacity:
    """The capacity of the vertiport of ``cfg`` (a validated config, its rules applied)."""
    layout = Layout.from_config(cfg)
    energy = FlightEnergy(cfg, layout)
    bat, sc = cfg.battery, cfg.schedule
    n = cfg.fleet_size
    chargers = len(cfg.layout.charging_ports_xy_m)
    minutes = sc.minutes_per_step
    trip_pct = float(energy.trip_pct.mean())
    trip_min = float(energy.trip_steps.mean()) * minutes
    charge_pct_per_min = bat.charge_pct * (1.0 - cfg.uncertainty.charger_failure_prob) / minutes
    hover_per_min, idle_per_min = bat.hover_drain_pct / minutes, bat.ground_idle_drain_pct / minutes

    turnaround = sum(sc.takeoff_after_landing_min) / 2.0  # schedule minutes
    reserve = cfg.atc.energy_reserve_pct

    def cycle(gap: float) -> tuple[float, float, float]:
        energy_pct = trip_pct + hover_per_min * gap / 2.0
        charge = energy_pct / charge_pct_per_min if charge_pct_per_min > 0 else math.inf
        pad = max(turnaround, charge, gap)
        return energy_pct, pad, trip_min + pad + gap / 2.0

    gap = n * minutes
    if cfg.atc.skip_agents_without_decision:  # a fixed point: the gap sets the share away
        away_min = max(trip_min - _inside_min(cfg), 0.0)
        for _ in range(50):
            _, _, cyc = cycle(gap)
            gap = max(n * (1.0 - away_min / cyc), 1.0) * minutes
    energy_pct, pad_min, cycle_min = cycle(gap)
    utilisation = n * pad_min / cycle_min / chargers
    hover_wait, idle_wait = hover_per_min * gap, idle_per_min * gap
    normal = len(cfg.layout.normal_ports_xy_m)
    returned = 100.0 - energy_pct  # a vehicle that left full, on the ground again
    stuck = normal > 0 and returned - idle_wait < trip_pct + reserve
    if trip_pct + hover_wait + reserve > 100.0:
        verdict, reason = "overloaded", (f"a trip ({trip_pct:.0f} %), a turn gap of hovering "
                                         f"({hover_wait:.0f} %) and the reserve exceed a battery")
    elif stuck and utilisation > MARGINAL_UTILISATION:
        verdict, reason = "overloaded", (
            f"the charging ports are busy {utilisation:.0%} of the time, so vehicles land on "
            f"normal ports, where a turn gap idling ({idle_wait:.0f} %) leaves less than a trip "
            "and the reserve")
    elif stuck:
        verdict, reason = "marginal", ("a vehicle that lands on a normal port cannot fly again "
                                       "before it charges")
    elif utilisation > 1.0:
        verdict, reason = "marginal", f"the charging ports are busy {utilisation:.0%} of the time"
    else:
        verdict, reason = "carried", (f"the charging ports are busy {utilisation:.0%} of the "
                                      f"time; a turn gap costs {hover_wait:.0f} % hovering")
    return Capacity(name=cfg.name, fleet_size=n, chargers=chargers, normal_ports=normal,
                    turn_gap_min=gap, trip_min=trip_min, trip_pct=trip_pct, energy_pct=energy_pct,
                    charger_min=pad_min, cycle_min=cycle_min, utilisation=utilisation,
                    hover_wait_pct=hover_wait, idle_wait_pct=idle_wait, verdict=verdict,
                    reason=reason)


def _inside_min(cfg: EnvConfig) -> float:
    """Minutes of a trip spent inside the airspace (climb, out to the boundary, back in to the
    hover spot and down): the share of a trip a vehicle is not away, estimated as the airspace
    radius flown twice and the climb and descent, at the cruise speed."""
    fl = cfg.flight
    step_m = fl.cruise_speed_mps * fl.flight_seconds_per_step
    inside_m = 2.0 * cfg.layout.airspace_radius_m + fl.departure_altitude_m + fl.hover_altitude_m
    return inside_m / step_m * cfg.schedule.minutes_per_step


def table(rows: list[Capacity]) -> str:
    """A Markdown table of capacities, one row per config."""
    head = ("| config | eVTOLs | charging ports | normal ports | turn gap (min) | trip (min) | "
            "trip (%) | charger (min/cycle) | cycle (min) | utilisation | turn gap hovering (%) | "
            "turn gap idling (%) | verdict |")
    lines = [head, "|---|" + "---:|" * 11 + "---|"]
    for c in rows:
        lines.append(f"| `{c.name}` | {c.fleet_size} | {c.chargers} | {c.normal_ports} | "
                     f"{c.turn_gap_min:.0f} | {c.trip_min:.0f} | {c.trip_pct:.0f} | "
                     f"{c.charger_min:.1f} | {c.cycle_min:.0f} | {c.utilisation:.2f} | "
                     f"{c.hover_wait_pct:.0f} | {c.idle_wait_pct:.0f} | **{c.verdict}** |")
    return "\n".join(lines)
