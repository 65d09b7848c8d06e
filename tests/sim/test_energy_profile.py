"""The opt-in energy profile (docs/energy.md): the charge taper and the landing reserve, by hand;
their validation; the realistic configs against the published figures they come from; a day of
the dispatcher on them."""

import math
import re

import numpy as np
import pytest

from helpers import seed0_sim

from agents.controllers.episode import run_aec_episode
from agents.controllers.registry import make_controller
from marl_vertiport import ConfigError, load_config, vertiport_v1
from marl_vertiport.config import BatteryConfig
from marl_vertiport.sim.battery import BatteryModel
from marl_vertiport.sim.invariants import violations
from marl_vertiport.sim.schema import AIRBORNE, ON_CHARGER, ON_PORT, TAXIING, Status

STAY, TAKEOFF, CONTINUE = 0, 1, 12
# A taper that is easy to follow by hand: 10 %/step up to 80 %, 2 %/step at 100 %.
TAPER = BatteryConfig(charge_pct=10.0, charge_taper_start_pct=80.0, charge_taper_end_pct=2.0)


def model(battery: BatteryConfig) -> BatteryModel:
    return BatteryModel(battery, AIRBORNE, ON_PORT, ON_CHARGER)


# ------------------------------------------------------------------ the charge taper
@pytest.mark.parametrize("level, rate", [
    (0.0, 10.0), (79.9, 10.0), (80.0, 10.0),  # constant current up to the start
    (85.0, 8.0), (90.0, 6.0), (99.0, 2.4),    # 10 - 8 x (level - 80) / 20
    (100.0, 2.0),                             # the end rate at full
])
def test_the_charge_rate_falls_linearly_from_the_start_to_the_end(level, rate):
    assert model(TAPER).charge_rate_pct(level) == pytest.approx(rate)


def test_changes_read_the_level_only_on_a_working_charger():
    status = [Status.ON_CHARGER, Status.ON_CHARGER, Status.ON_CHARGER, Status.ON_PORT,
              Status.ON_CHARGER, Status.TAXIING]
    level = [50.0, 90.0, 99.0, 90.0, 95.0, 90.0]
    change = model(TAPER).changes(level, [int(s) for s in status], [(5, 2.0)],
                                  failed_charging=[4])
    # 10 below the start; 6 and 2.4 above it; idling -4 and a failed charger -4 whatever the
    # level; cruising 0.5 %/m x 0.25 x 2 m
    assert change == pytest.approx([10.0, 6.0, 2.4, -4.0, -4.0, -0.25])
    assert BatteryModel.apply(level, change) == pytest.approx([60.0, 96.0, 100.0, 86.0, 91.0,
                                                               89.75])


def test_without_a_taper_the_level_changes_nothing():
    default = model(BatteryConfig())
    assert BatteryConfig().charge_taper_start_pct == 100.0 and not default.tapers
    status = [int(s) for s in Status]
    rng = np.random.default_rng(0)
    for _ in range(20):
        level = rng.uniform(0.0, 100.0, len(status)).tolist()
        assert default.changes(level, status, []) == list(default.rate_pct)
    assert default.charge_rate_pct(99.9) == 10.0


def test_a_vehicle_on_the_charger_charges_through_the_taper_step_by_step():
    sim = seed0_sim(**{"battery.charge_taper_start_pct": 80.0,
                       "battery.charge_taper_end_pct": 2.0})
    assert sim.status[0] == ON_CHARGER
    sim.battery[0] = 75.0
    seen = []
    for _ in range(4):
        sim.acting = 1  # evtol_1 stays on its normal port; evtol_0 charges
        sim.step(STAY)
        seen.append(float(sim.battery[0]))
    # 75 + 10; 85 + (10 - 8 x 5/20); 93 + (10 - 8 x 13/20); 97.8 + 2.88 clipped at 100
    assert seen == pytest.approx([85.0, 93.0, 97.8, 100.0])


# ------------------------------------------------------------------ validation
@pytest.mark.parametrize("override, message", [
    ({"battery.charge_taper_start_pct": 120.0},
     r"battery\.charge_taper_start_pct: must lie in \[0, 100\], got 120"),
    ({"battery.charge_taper_start_pct": -1.0}, r"battery\.charge_taper_start_pct: must lie in"),
    ({"battery.charge_taper_end_pct": 11.0},
     r"battery\.charge_taper_end_pct: must lie in \[0, battery\.charge_pct = 10\] .*got 11"),
    ({"battery.charge_taper_end_pct": -0.5}, r"battery\.charge_taper_end_pct: must lie in"),
    ({"battery.landing_reserve_pct": 101.0},
     r"battery\.landing_reserve_pct: must lie in \[0, 100\], got 101"),
    ({"battery.landing_reserve_pct": -1.0}, r"battery\.landing_reserve_pct: must lie in"),
])
def test_bad_taper_and_reserve_values_name_the_field(override, message):
    with pytest.raises(ConfigError, match="^" + message):
        load_config("paper", **override)


def test_a_bad_value_in_a_file_names_the_file_and_the_field(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("base: realistic\nname: mine\nbattery:\n  charge_taper_end_pct: 5.0\n")
    field = r": battery\.charge_taper_end_pct: must lie in \[0, battery\.charge_pct = 3\.81\]"
    with pytest.raises(ConfigError, match=re.escape(str(path)) + field):
        load_config(path)


# ------------------------------------------------------------------ the landing reserve
def land_evtol_3(battery_pct: float, **overrides):
    """seed0_sim (rules v0): evtol_2 takes off from normal port 0, then evtol_3 lands there from
    hover spot 7 with ``battery_pct``. Returns the sim and evtol_3's battery at touchdown, by
    hand: 2 m pieces at 4 m altitude (0.5 %/m), the last one shorter, then down 3.85 m."""
    sim = seed0_sim(**overrides)
    sim.acting = 2
    sim.step(TAKEOFF)
    sim.battery[3] = battery_pct
    sim.acting = 3
    _, info = sim.step(2 + 0)  # land on normal port 0
    while sim.status[3] == TAXIING:
        sim.acting = 3
        _, info = sim.step(CONTINUE)
    assert info["touchdowns"] == 1 and sim.metrics.completed_trips == 1
    d = float(np.linalg.norm(sim.layout.node_xy_m[7] - sim.layout.node_xy_m[0]))
    pieces = [2.0] * math.floor(d / 2.0) + [d - 2.0 * math.floor(d / 2.0), 2.0, 1.85]
    landed = battery_pct - sum(0.5 * p if p >= 1.0 else 2.0 for p in pieces)
    assert float(sim.battery[3]) == pytest.approx(landed)
    return sim, landed


def test_a_trip_counts_when_it_touches_down_below_the_reserve():
    _, landed = land_evtol_3(40.0)
    below, _ = land_evtol_3(40.0, **{"battery.landing_reserve_pct": landed + 0.01})
    at, _ = land_evtol_3(40.0, **{"battery.landing_reserve_pct": landed - 1e-9})
    assert below.metrics.reserve_violations == 1
    assert below.episode_metrics()["reserve_violations"] == 1
    assert at.metrics.reserve_violations == 0  # strictly below counts; at or above does not


def test_the_invariants_refuse_more_landings_below_the_reserve_than_trips():
    sim, _ = land_evtol_3(40.0)
    assert violations(sim) == []
    sim.metrics.reserve_violations = 2
    assert violations(sim) == ["2 landings below the reserve in 1 completed trips"]


def test_without_a_reserve_no_landing_counts():
    sim, landed = land_evtol_3(12.0)
    assert landed < 10.0 and sim.metrics.reserve_violations == 0


def test_a_hop_between_pads_is_not_a_landing():
    sim = seed0_sim(**{"battery.landing_reserve_pct": 90.0})
    sim.acting = 2
    sim.step(TAKEOFF)  # frees normal port 0
    sim.battery[1] = 50.0
    sim.acting = 1
    sim.step(2 + 0)  # evtol_1 hops from normal port 1 to normal port 0: no landing clearance
    while sim.status[1] == TAXIING:
        sim.acting = 1
        sim.step(CONTINUE)
    assert sim.status[1] == ON_PORT and sim.node[1] == 0 and sim.battery[1] < 90.0
    assert sim.metrics.reserve_violations == 0 and sim.metrics.completed_trips == 0


# ------------------------------------------------------------------ the realistic configs
def test_the_realistic_numbers_are_the_published_figures_per_minute():
    bat = load_config("realistic").battery
    pack_kwh, cruise_kw, lift_kw, charger_kw = 140.0, 71.0, 500.0, 320.0

    def pct_per_min(kw):
        return 100.0 * kw / 60.0 / pack_kwh

    step_m = 8.0 * 0.25  # the paper's cruise speed times the flight time of a step
    assert bat.cruise_drain_pct_per_m * bat.cruise_drain_scale * step_m == pytest.approx(
        pct_per_min(cruise_kw), abs=1e-3)
    assert bat.hover_drain_pct == pytest.approx(pct_per_min(lift_kw), abs=0.01)
    assert bat.charge_pct == pytest.approx(pct_per_min(charger_kw), abs=0.01)
    assert bat.charge_taper_end_pct == pytest.approx(0.03 * bat.charge_pct, abs=0.01)
    assert bat.landing_reserve_pct == pytest.approx(30 * pct_per_min(cruise_kw), abs=0.05)
    assert (bat.charge_taper_start_pct, bat.ground_idle_drain_pct) == (80.0, 0.0)
    uncertain = load_config("realistic_uncertain")
    assert uncertain.battery == bat
    assert load_config("paper_uncertain").uncertainty == uncertain.uncertainty
    # the same energy under either rules version: no scale for rules v0 to undo
    from marl_vertiport.config import with_rules
    assert with_rules(load_config("realistic"), 0).battery == bat


def test_a_day_of_the_dispatcher_on_the_realistic_profile_is_legal_and_counts_reserves():
    env = vertiport_v1.env(config="realistic")
    problems, reserve, last = [], [], []

    def check(agent, action, env):
        sim = env.unwrapped.sim
        problems.extend(violations(sim))
        reserve.append(sim.metrics.reserve_violations)
        last[:] = [info.get("episode") for info in env.infos.values()]

    try:
        metrics = run_aec_episode(env, make_controller("dispatcher"), seed=800000,
                                  on_step=check)
    finally:
        env.close()
    assert problems == []
    assert metrics["steps"] == 1440 and len(reserve) == 1440
    assert last and all(e["reserve_violations"] == metrics["reserve_violations"] for e in last)
    assert np.all(np.diff(reserve) >= 0)  # a count that only grows
    assert 0 <= metrics["reserve_violations"] <= metrics["completed_trips"]
    assert list(metrics).index("reserve_violations") == list(metrics).index("stranded") + 1
