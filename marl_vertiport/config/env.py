"""The env config's schema: the vertiport's layout, flight, schedule, battery, reward, safety,
uncertainty and ATC settings as frozen dataclasses, their physical bounds, and
:func:`load_config`.

YAML files in ``configs/env/`` hold the values; the dataclasses below are the schema.
Loading checks every key and type and every physical bound, and the error names the field
(``layout.charging_ports_xy_m: ...``), so a broken file never produces a half-built env.

Units are in the field names: ``_m`` metres, ``_mps`` metres per second, ``_s`` seconds,
``_min`` schedule minutes, ``_pct`` battery percent, ``_prob`` probabilities in [0, 1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from marl_vertiport.config.typed import (
    ConfigError, UnknownKeyError, build_dataclass, read_yaml, resolve_path, set_dotted, to_dict,
)

#: Folder with the shipped environment configs (``paper.yaml``, ``paper_uncertain.yaml``, ...),
#: inside the package so that an installed wheel finds them too (``configs/env/`` in the
#: repository links here).
CONFIG_DIR = Path(str(resources.files("marl_vertiport").joinpath("configs")))


# --------------------------------------------------------------------------------------
# Schema
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LayoutConfig:
    """Where things are. Ports and hover spots form the vertiport graph, in this order:
    normal ports, charging ports, hover spots."""

    normal_ports_xy_m: tuple[tuple[float, float], ...] = ((-6.0, 0.0), (6.0, 0.0))
    """Ground positions of the normal (non-charging) landing ports."""
    charging_ports_xy_m: tuple[tuple[float, float], ...] = ((0.0, 8.0),)
    """Ground positions of the charging (battery) ports; at least one."""
    hover_spots_xy_m: tuple[tuple[float, float], ...] = ()
    """Hover spot positions; empty means a ring of ``hover_ring_count`` spots."""
    hover_ring_count: int = 7
    """Number of hover spots on the ring, used when ``hover_spots_xy_m`` is empty."""
    hover_ring_radius_m: float = 12.0
    """Radius of the hover-spot ring around the vertiport centre."""
    destinations_xy_m: tuple[tuple[float, float], ...] = ()
    """Destinations outside the airspace; empty means a ring of ``destination_ring_count``."""
    destination_ring_count: int = 5
    """Number of destinations on the outer ring, used when ``destinations_xy_m`` is empty."""
    destination_ring_radius_m: float = 35.0
    """Radius of the destination ring."""
    airspace_radius_m: float = 20.0
    """Radius of the vertiport airspace; vehicles beyond it fly a kinematic model."""


@dataclass(frozen=True)
class FlightConfig:
    """Flight physics and the mapping between schedule time and flight time."""

    cruise_speed_mps: float = 8.0
    """Speed of every vehicle in flight, horizontal or vertical."""
    flight_seconds_per_step: float = 0.25
    """Seconds of physical flight simulated per decision step (one schedule minute)."""
    physics_rate_hz: float = 48.0
    """Physics update rate of the flight engine: at least 45 Hz (the paper's floor) unless
    ``allow_low_physics_rate``, at most 2000 Hz."""
    allow_low_physics_rate: bool = False
    """Accept a physics rate under the paper's 45 Hz floor (a coarser, faster engine for quick
    experiments; not the paper's model)."""
    hover_altitude_m: float = 4.0
    """Altitude of hover spots and of moves between ports and hover spots."""
    transit_altitude_m: float = 8.0
    """Rules v0: altitude of departures to and arrivals from the airspace boundary."""
    departure_altitude_m: float = 8.0
    """Rules v1: altitude of departures, from the pad's climb to the airspace boundary: above
    the arrivals by at least the vertical clearance (``safety.min_separation_m`` +
    ``atc.vertical_buffer_m``), so a departure's level leg clears every arrival it passes over
    (rules v0: the transit altitude)."""
    arrival_altitude_m: float = 4.0
    """Rules v1: altitude of arrivals, from the holding slot straight across to the hover spot
    (at the hover altitude: no descent at the spot; rules v0: the transit altitude)."""
    avoid_altitudes_m: tuple[float, ...] = (12.0, 16.0)
    """Altitude layers used by the "avoid collision" action, lowest free layer first."""
    vehicle_size_m: float = 1.0
    """Edge of the square footprint of a vehicle (the paper: 1 x 1 m)."""
    vehicle_height_m: float = 0.3
    """Height of the vehicle's collision box."""
    vehicle_mass_kg: float = 1.0
    """Mass of a vehicle's rigid body (scales gust forces; motion is speed-commanded)."""


@dataclass(frozen=True)
class ScheduleConfig:
    """Flight plans and schedule windows, in schedule minutes."""

    episode_steps: int = 1440
    """Decision steps per episode (one day of one-minute steps); ends by truncation."""
    minutes_per_step: float = 1.0
    """Schedule minutes per decision step."""
    initial_takeoff_min: tuple[int, int] = (5, 20)
    """Range (inclusive) of the first take-off time of vehicles that start on a port."""
    takeoff_after_landing_min: tuple[int, int] = (10, 20)
    """Range (inclusive) of the next take-off time, counted from touchdown."""
    landing_window_min: int = 15
    """A vehicle re-entering the airspace is scheduled to land this many minutes later."""
    on_time_tolerance_min: int = 5
    """An operation is on time within this many minutes of its scheduled time."""


@dataclass(frozen=True)
class BatteryConfig:
    """Battery model in percent of capacity per decision step."""

    initial_pct: float = 100.0
    """Charge of every vehicle at the start of an episode."""
    cruise_drain_pct_per_m: float = 0.5
    """Drain per metre flown when cruising (the paper's eq. 1), before ``cruise_drain_scale``."""
    cruise_drain_scale: float = 0.25
    """Rules v1: the fraction of each metre flown that the cruise drain charges, so that an
    operation costs the battery what it costs in the paper's code, whose destinations lie 8-11 m
    away: a round trip here, take-off to a hover spot, covers about four times the distance
    (``docs/battery-and-uncertainty.md``, section 8.1). Rules v0: 1 (so is it in the ``paper_overloaded``
    stress scenario)."""
    hover_drain_pct: float = 2.0
    """Drain of an airborne vehicle that moved less than ``min_cruise_distance_m``."""
    ground_idle_drain_pct: float = 4.0
    """Drain of a vehicle idling on a normal port (or a failed charger)."""
    charge_pct: float = 10.0
    """Charge gained per step on a working charging port (below ``charge_taper_start_pct``)."""
    min_cruise_distance_m: float = 1.0
    """Below this distance in a step an airborne vehicle counts as hovering."""
    charge_taper_start_pct: float = 100.0
    """Above this charge the charge per step falls linearly, from ``charge_pct`` here to
    ``charge_taper_end_pct`` at 100 % (the constant-voltage phase of a lithium-ion charge), read
    at the level the step starts from; 100: no taper, every step gains ``charge_pct``."""
    charge_taper_end_pct: float = 0.0
    """Charge per step at 100 % when the charge tapers; at most ``charge_pct`` (a taper only
    slows the charge)."""
    landing_reserve_pct: float = 0.0
    """Battery a landing should leave: a completed trip that touches down below it counts in the
    episode metric ``reserve_violations``. Measured, never enforced (the ATC's energy check
    keeps its own margin, ``atc.energy_reserve_pct``); 0: no landing falls below it."""

    @property
    def cruise_pct_per_m(self) -> float:
        """Drain per metre flown when cruising: ``cruise_drain_pct_per_m`` times
        ``cruise_drain_scale``."""
        return self.cruise_drain_pct_per_m * self.cruise_drain_scale


@dataclass(frozen=True)
class RewardConfig:
    """Reward terms of the paper: R = w1 tau + w2 gamma + w3 lambda + w4 beta + w5 S."""

    takeoff_weight: float = 0.3
    landing_weight: float = 0.3
    battery_weight: float = 0.35
    delay_weight: float = 0.1
    safety_weight: float = 0.35
    term_magnitude: float = 5.0
    """Each term lies in [-term_magnitude, +term_magnitude]."""
    battery_threshold_pct: float = 30.0
    """Below this charge lambda is the penalty and a take-off or landing is not "good"."""


@dataclass(frozen=True)
class SafetyConfig:
    min_separation_m: float = 3.0
    """Minimum separation between vehicles; the conflict threshold of the safety term."""


@dataclass(frozen=True)
class UncertaintyConfig:
    """The paper's case-2 uncertainties; every draw comes from the env's seeded generator."""

    wind_gust_prob: float = 0.0
    """Chance per flying vehicle per step of a gust against its motion."""
    gust_speed_loss_range: tuple[float, float] = (0.2, 2.0)
    """Fraction of the step's planned displacement a gust takes away: 1 stops, 2 reverses."""
    charger_failure_prob: float = 0.0
    """Chance per charging port per step that it does not charge."""
    takeoff_failure_prob: float = 0.0
    """Chance that a take-off action fails and the vehicle stays on its port."""
    position_noise_mean_m: float = 0.0
    """Mean of the Gaussian error added to observed x and y of vehicles (paper draft: 1 m)."""
    position_noise_std_m: float = 0.0
    """Standard deviation of that error (paper draft: 1 m); 0 with mean 0 disables it."""
    action_misread_prob: float = 0.0
    """Chance that the commanded action is replaced by another legal one (paper draft: 0.05)."""
    common_random_numbers: bool = False
    """True: every draw after the day's first state comes from a stream keyed by what it is for
    (a vehicle's k-th trip or take-off, a step's gusts and charger failures), so every
    controller on the same seed meets the same luck; False: one stream, in the order the day's
    decisions call for draws (every shipped result)."""


@dataclass(frozen=True)
class ATCConfig:
    skip_agents_without_decision: bool = False
    """False (paper): the turn of a vehicle outside the airspace is spent waiting for it.
    True: the turn passes to the next vehicle in round-robin order that has a decision."""
    energy_check: bool = True
    """True: the action mask clears a take-off or a move to a node only if the battery, less
    ``energy_reserve_pct``, covers the whole flight (without gusts). False (paper): no check."""
    energy_reserve_pct: float = 5.0
    """Battery an energy-checked flight must have left over (covers gusts), percent."""
    separation_check: bool = True
    """Rules v1: clear a flight only if its protected volume clears every other vehicle's
    reserved volume (:mod:`marl_vertiport.sim.clearance`); arrivals hold in slots of their own.
    False (rules v0, the paper): no check."""
    horizontal_buffer_m: float = 1.0
    """Rules v1: horizontal distance two protected volumes keep beyond
    ``safety.min_separation_m`` (where their altitude ranges are closer than the vertical
    threshold)."""
    vertical_buffer_m: float = 0.5
    """Rules v1: vertical distance two protected volumes keep beyond ``safety.min_separation_m``
    (where they are closer horizontally than the horizontal threshold); small enough that
    flight layers 4 m apart and a move at 4 m above a parked vehicle (3.85 m) stay clear."""
    along_track_margin_m: float = 2.0
    """Rules v1: each segment of a protected volume extends this far behind its start, and a
    reversing gust pushes a vehicle back no farther (one step of flight at cruise speed)."""
    trail_departures: bool = True
    """Rules v1: a flight may be cleared behind a departing vehicle whose reservation it does not
    clear (a departure leaves the airspace, and its reservation only shrinks until then); the
    simulator holds the follower, each step, wherever its next step of flight would not clear
    that reservation. False: every reservation must be clear at the clearance (whole-leg
    reservations only)."""
    trail_chains: bool = True
    """Rules v1, with ``trail_departures``: True: a flight may be cleared behind a departure that
    itself still waits behind another (holds then chain: each waits for the one ahead). False:
    only behind departures that wait for none, so a hold lasts at most one departure's climb and
    exit; a flight whose volume meets a waiting departure's reservation is not cleared."""
    holding_slots: int = 0
    """Rules v1: holding slots at the airspace boundary, at the arrival altitude; 0: one per
    vehicle (at least one per destination), as many as fit ``2 x`` the horizontal threshold
    apart."""


@dataclass(frozen=True)
class EnvConfig:
    """The whole environment. ``fleet_size`` eVTOLs, the layout, and the models."""

    name: str = "paper"
    fleet_size: int = 4
    layout: LayoutConfig = field(default_factory=LayoutConfig)
    flight: FlightConfig = field(default_factory=FlightConfig)
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    battery: BatteryConfig = field(default_factory=BatteryConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)
    atc: ATCConfig = field(default_factory=ATCConfig)

    def __post_init__(self) -> None:
        _validate(self)

    def replace(self, **overrides: Any) -> EnvConfig:
        """Return a copy with dotted-key overrides, e.g. ``{"uncertainty.wind_gust_prob": 0.1}``
        or section dicts ``uncertainty={"wind_gust_prob": 0.1}``.

        Raises:
            UnknownKeyError: a key or section that does not exist (the known ones listed).
            ConfigError: a value the schema refuses, the field named."""
        data = to_dict(self)
        for key, value in overrides.items():
            try:
                set_dotted(data, key.replace("__", ".") if isinstance(key, str) else key, value)
            except UnknownKeyError as exc:
                exc.keyword = key
                raise
        return from_dict(data)


# --------------------------------------------------------------------------------------
# Validation of values
# --------------------------------------------------------------------------------------


#: Most vehicles, hover spots or destinations a config may ask for (a bound on the arrays a
#: layout allocates; the shipped configs use at most 40).
MAX_COUNT = 1000
#: Most engine substeps per decision step (flight seconds per step times the physics rate): the
#: shipped configs use 12; far more makes a step take seconds.
MAX_SUBSTEPS = 2000
#: Shortest distance a vehicle may cover in a step (cruise speed times flight time per step).
MIN_STEP_M = 0.01
#: The paper's floor for the physics update rate ("at least 45 Hz").
PHYSICS_RATE_FLOOR_HZ = 45.0
#: The highest physics rate accepted: above it a step's substeps cost time for no accuracy.
PHYSICS_RATE_MAX_HZ = 2000.0


def _check(cond: bool, fieldname: str, msg: str) -> None:
    if not cond:
        raise ConfigError(f"{fieldname}: {msg}")


def _check_spacing(cfg: EnvConfig) -> None:
    """Pads (normal and charging ports) and hover spots must stand at least a vehicle size plus
    the minimum separation apart, each kind among its own (hover spots are 4 m up, pads on the
    ground): two vehicles parked or hovering side by side are then never in a loss of
    separation, and never inside one another."""
    lay = cfg.layout
    spacing = cfg.flight.vehicle_size_m + cfg.safety.min_separation_m
    rule = (f"must stand at least vehicle_size_m + safety.min_separation_m = {spacing:g} m "
            "from every other")
    pads = [(f"layout.normal_ports_xy_m[{i}]", xy) for i, xy in enumerate(lay.normal_ports_xy_m)]
    pads += [(f"layout.charging_ports_xy_m[{i}]", xy) for i, xy in enumerate(lay.charging_ports_xy_m)]
    spots = [(f"layout.hover_spots_xy_m[{i}]", xy) for i, xy in enumerate(lay.hover_spots_xy_m)]
    for group, kind in ((pads, "pad"), (spots, "hover spot")):
        for i, (name_a, a) in enumerate(group):
            for name_b, b in group[i + 1:]:
                d = math.dist(a, b)
                _check(d >= spacing, name_b, f"is {d:g} m from {name_a}: a {kind} {rule}")
    if not lay.hover_spots_xy_m and lay.hover_ring_count >= 2:
        chord = 2.0 * lay.hover_ring_radius_m * math.sin(math.pi / lay.hover_ring_count)
        _check(chord >= spacing, "layout.hover_ring_radius_m",
               f"{lay.hover_ring_count} spots on a ring of {lay.hover_ring_radius_m:g} m stand "
               f"{chord:.3g} m apart: a hover spot {rule}")
    # A vehicle hovering at a spot and one parked on a pad: at least the separation apart in 3-D,
    # counting the hover altitude less a vehicle size (conservative) as their height apart. Ring
    # spots stand where sim.layout.ring puts them (phase pi / count); config cannot import sim.
    n, r = lay.hover_ring_count, lay.hover_ring_radius_m
    hover = [(name, "", xy) for name, xy in spots] or [
        ("layout.hover_ring_radius_m", f"spot {k} of the ring ",
         (r * math.cos(math.pi / n + 2.0 * math.pi * k / n),
          r * math.sin(math.pi / n + 2.0 * math.pi * k / n)))
        for k in range(n)]
    height = max(0.0, cfg.flight.hover_altitude_m - cfg.flight.vehicle_size_m)
    for field_name, label, s_xy in hover:
        for name_p, p_xy in pads:
            d = math.hypot(math.dist(s_xy, p_xy), height)
            _check(d >= cfg.safety.min_separation_m, field_name,
                   f"{label}is {d:.3g} m from {name_p} in 3-D (hovering {height:g} m above it, "
                   f"counting a vehicle size): less than safety.min_separation_m = "
                   f"{cfg.safety.min_separation_m:g} m")


def _validate(cfg: EnvConfig) -> None:
    lay, fl, sc, bat, rw, sf, un = (
        cfg.layout, cfg.flight, cfg.schedule, cfg.battery, cfg.reward, cfg.safety, cfg.uncertainty
    )
    _check(1 <= cfg.fleet_size <= MAX_COUNT, "fleet_size",
           f"must lie in [1, {MAX_COUNT}], got {cfg.fleet_size}")
    for name in ("hover_ring_count", "destination_ring_count"):
        _check(getattr(lay, name) <= MAX_COUNT, f"layout.{name}",
               f"must be <= {MAX_COUNT}, got {getattr(lay, name)}")
    _check(len(lay.charging_ports_xy_m) >= 1, "layout.charging_ports_xy_m",
           "the vertiport needs at least one charging port")
    n_hover = len(lay.hover_spots_xy_m) or lay.hover_ring_count
    n_dest = len(lay.destinations_xy_m) or lay.destination_ring_count
    _check(n_dest >= 1, "layout.destination_ring_count", "at least one destination is needed")
    _check(n_hover >= 0, "layout.hover_ring_count", "must be >= 0")
    n_ports = len(lay.normal_ports_xy_m) + len(lay.charging_ports_xy_m)
    _check(n_ports + n_hover >= cfg.fleet_size, "fleet_size",
           f"{cfg.fleet_size} vehicles do not fit on {n_ports} ports and {n_hover} hover spots")
    _check(lay.airspace_radius_m > 0, "layout.airspace_radius_m", "must be > 0")
    for name in ("hover_ring_radius_m", "destination_ring_radius_m"):
        _check(getattr(lay, name) > 0, f"layout.{name}", "must be > 0")
    for name in ("normal_ports_xy_m", "charging_ports_xy_m", "hover_spots_xy_m"):
        for i, xy in enumerate(getattr(lay, name)):
            _check(float(xy[0]) ** 2 + float(xy[1]) ** 2 < lay.airspace_radius_m ** 2,
                   f"layout.{name}[{i}]", "lies outside the airspace")
    for i, xy in enumerate(lay.destinations_xy_m):
        _check(float(xy[0]) ** 2 + float(xy[1]) ** 2 > lay.airspace_radius_m ** 2,
               f"layout.destinations_xy_m[{i}]", "must lie outside the airspace")
    if not lay.hover_spots_xy_m:
        _check(lay.hover_ring_radius_m < lay.airspace_radius_m, "layout.hover_ring_radius_m",
               "the hover ring must lie inside the airspace")
    if not lay.destinations_xy_m:
        _check(lay.destination_ring_radius_m > lay.airspace_radius_m,
               "layout.destination_ring_radius_m", "destinations must lie outside the airspace")

    for name in ("cruise_speed_mps", "flight_seconds_per_step", "physics_rate_hz",
                 "hover_altitude_m", "transit_altitude_m", "vehicle_size_m",
                 "vehicle_height_m", "vehicle_mass_kg"):
        _check(getattr(fl, name) > 0, f"flight.{name}", f"must be > 0, got {getattr(fl, name)}")
    if not fl.allow_low_physics_rate:
        _check(fl.physics_rate_hz >= PHYSICS_RATE_FLOOR_HZ, "flight.physics_rate_hz",
               f"must be >= {PHYSICS_RATE_FLOOR_HZ:g} Hz (the paper's floor), got "
               f"{fl.physics_rate_hz:g}; set flight.allow_low_physics_rate: true to go below it")
    _check(fl.physics_rate_hz <= PHYSICS_RATE_MAX_HZ, "flight.physics_rate_hz",
           f"must be <= {PHYSICS_RATE_MAX_HZ:g} Hz, got {fl.physics_rate_hz:g}")
    step_m = fl.cruise_speed_mps * fl.flight_seconds_per_step
    _check(step_m >= MIN_STEP_M, "flight.flight_seconds_per_step",
           f"a step of {fl.flight_seconds_per_step:g} s at {fl.cruise_speed_mps:g} m/s covers "
           f"{step_m:.3g} m; at least {MIN_STEP_M:g} m is needed for a vehicle to get anywhere")
    substeps = fl.flight_seconds_per_step * fl.physics_rate_hz
    _check(substeps <= MAX_SUBSTEPS, "flight.flight_seconds_per_step",
           f"{fl.flight_seconds_per_step:g} s of flight per step at {fl.physics_rate_hz:g} Hz is "
           f"{substeps:.3g} engine substeps per step; at most {MAX_SUBSTEPS} are allowed")
    for name in ("hover_altitude_m", "transit_altitude_m"):
        _check(getattr(fl, name) > fl.vehicle_height_m, f"flight.{name}",
               f"must be above the vehicle's height ({fl.vehicle_height_m:g} m), so that a vehicle "
               f"there is off the ground; got {getattr(fl, name):g}")
    _check_spacing(cfg)
    _check(len(fl.avoid_altitudes_m) >= 1, "flight.avoid_altitudes_m", "needs at least one layer")
    for i, alt in enumerate(fl.avoid_altitudes_m):
        _check(alt > fl.transit_altitude_m, f"flight.avoid_altitudes_m[{i}]",
               "avoidance layers must lie above the transit altitude")
        _check(i == 0 or alt > fl.avoid_altitudes_m[i - 1], f"flight.avoid_altitudes_m[{i}]",
               "layers must be listed from lowest to highest")

    _check(sc.episode_steps >= 1, "schedule.episode_steps", "must be >= 1")
    _check(sc.minutes_per_step > 0, "schedule.minutes_per_step", "must be > 0")
    for name in ("initial_takeoff_min", "takeoff_after_landing_min"):
        lo, hi = getattr(sc, name)
        _check(0 <= lo <= hi, f"schedule.{name}", f"needs 0 <= low <= high, got {[lo, hi]}")
    _check(sc.landing_window_min >= 0, "schedule.landing_window_min", "must be >= 0")
    _check(sc.on_time_tolerance_min >= 0, "schedule.on_time_tolerance_min", "must be >= 0")

    _check(0 <= bat.initial_pct <= 100, "battery.initial_pct", "must lie in [0, 100]")
    for name in ("cruise_drain_pct_per_m", "cruise_drain_scale", "hover_drain_pct",
                 "ground_idle_drain_pct", "charge_pct", "min_cruise_distance_m"):
        _check(getattr(bat, name) >= 0, f"battery.{name}", "must be >= 0")
    for name in ("charge_taper_start_pct", "landing_reserve_pct"):
        _check(0 <= getattr(bat, name) <= 100, f"battery.{name}",
               f"must lie in [0, 100], got {getattr(bat, name):g}")
    _check(0 <= bat.charge_taper_end_pct <= bat.charge_pct, "battery.charge_taper_end_pct",
           f"must lie in [0, battery.charge_pct = {bat.charge_pct:g}] (a taper only slows the "
           f"charge), got {bat.charge_taper_end_pct:g}")

    for name in ("takeoff_weight", "landing_weight", "battery_weight", "delay_weight",
                 "safety_weight", "term_magnitude"):
        _check(getattr(rw, name) >= 0, f"reward.{name}", "must be >= 0")
    _check(0 <= rw.battery_threshold_pct <= 100, "reward.battery_threshold_pct",
           "must lie in [0, 100]")
    _check(sf.min_separation_m > 0, "safety.min_separation_m", "must be > 0")

    for name in ("wind_gust_prob", "charger_failure_prob", "takeoff_failure_prob",
                 "action_misread_prob"):
        p = getattr(un, name)
        _check(0.0 <= p <= 1.0, f"uncertainty.{name}", f"is a probability, got {p}")
    lo, hi = un.gust_speed_loss_range
    _check(0 <= lo <= hi, "uncertainty.gust_speed_loss_range", f"needs 0 <= low <= high, got {[lo, hi]}")
    _check(un.position_noise_std_m >= 0, "uncertainty.position_noise_std_m", "must be >= 0")
    reserve = cfg.atc.energy_reserve_pct
    _check(0 <= reserve <= 100, "atc.energy_reserve_pct", f"must lie in [0, 100], got {reserve}")
    atc = cfg.atc
    for name in ("horizontal_buffer_m", "vertical_buffer_m", "along_track_margin_m"):
        _check(getattr(atc, name) >= 0, f"atc.{name}", f"must be >= 0, got {getattr(atc, name)}")
    _check(atc.holding_slots >= 0, "atc.holding_slots", f"must be >= 0, got {atc.holding_slots}")
    for name in ("departure_altitude_m", "arrival_altitude_m"):
        _check(getattr(fl, name) > fl.vehicle_height_m, f"flight.{name}",
               f"must be above the vehicle's height ({fl.vehicle_height_m:g} m), got "
               f"{getattr(fl, name):g}")


def from_dict(data: dict[str, Any]) -> EnvConfig:
    """Build and validate an :class:`EnvConfig` from plain data (as loaded from YAML)."""
    return build_dataclass(EnvConfig, data)


def load_config(config: str | Path | EnvConfig | dict | None = None, **overrides: Any) -> EnvConfig:
    """Resolve ``config`` into a validated :class:`EnvConfig`.

    Args:
        config: ``None`` (the paper's case 1), an :class:`EnvConfig`, a dict, a path to a YAML
            file, or the name of a file in ``configs/env/`` (``"paper"``, ``"paper_uncertain"``).
        **overrides: dotted keys (``uncertainty.wind_gust_prob``, or ``uncertainty__...`` as a
            Python keyword) or whole sections as dicts, applied on top.
    """
    if config is None:
        config = "paper"
    if isinstance(config, EnvConfig):
        cfg = config
    elif isinstance(config, dict):
        cfg = from_dict(config)
    else:
        path = resolve_path(config, CONFIG_DIR)
        data = read_yaml(path, CONFIG_DIR)
        try:
            cfg = from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from exc
    if overrides:
        cfg = cfg.replace(**overrides)
    return cfg
