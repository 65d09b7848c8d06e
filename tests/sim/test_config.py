"""Every shipped YAML loads; broken configs fail at load with the field named."""

import re
from pathlib import Path

import pytest

from marl_vertiport import ConfigError, load_config
from marl_vertiport.config import CONFIG_DIR, EnvConfig

ALL_CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))


@pytest.mark.parametrize("path", ALL_CONFIGS, ids=lambda p: p.stem)
def test_every_shipped_config_loads(path):
    cfg = load_config(path)
    assert isinstance(cfg, EnvConfig)


#: Env configs of studies that are not shipped scenarios, kept with their experiments.
STUDY_CONFIG = (Path(__file__).resolve().parents[2] / "experiments" / "vertiport-capacity"
                / "configs" / "fleet40_all_pads_charging.yaml")


def test_the_forty_charger_study_gives_every_vehicle_a_charging_port():
    cfg = load_config(STUDY_CONFIG)
    assert cfg.fleet_size == len(cfg.layout.charging_ports_xy_m) == 40
    assert len(cfg.layout.normal_ports_xy_m) == 0
    assert cfg.schedule.minutes_per_step == 0.25 and cfg.schedule.episode_steps == 5760
    assert cfg.battery.hover_drain_pct / cfg.schedule.minutes_per_step == 2.0  # per minute


def test_paper_defaults_match_the_paper():
    cfg = load_config("paper")
    assert cfg.fleet_size == 4
    assert len(cfg.layout.normal_ports_xy_m) == 2 and len(cfg.layout.charging_ports_xy_m) == 1
    assert cfg.layout.hover_ring_count == 7 and cfg.layout.destination_ring_count == 5
    r = cfg.reward
    assert (r.takeoff_weight, r.landing_weight, r.battery_weight, r.delay_weight,
            r.safety_weight) == (0.3, 0.3, 0.35, 0.1, 0.35)
    assert cfg.schedule.episode_steps == 1440
    assert cfg.schedule.takeoff_after_landing_min == (10, 20)
    assert cfg.schedule.landing_window_min == 15
    assert cfg.flight.physics_rate_hz >= 45
    b = cfg.battery
    assert (b.cruise_drain_pct_per_m, b.hover_drain_pct, b.ground_idle_drain_pct,
            b.charge_pct) == (0.5, 2.0, 4.0, 10.0)
    u = cfg.uncertainty
    assert u.wind_gust_prob == u.charger_failure_prob == u.takeoff_failure_prob == 0.0
    u2 = load_config("paper_uncertain").uncertainty
    assert u2.wind_gust_prob == u2.charger_failure_prob == u2.takeoff_failure_prob == 0.05


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cfg.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, field", [
    ("fleet_sise: 4\n", "fleet_sise"),
    ("fleet_size: four\n", "fleet_size"),
    ("layout:\n  charging_ports_xy_m: []\n", "layout.charging_ports_xy_m"),
    ("layout:\n  destination_ring_count: 0\n", "layout.destination_ring_count"),
    ("uncertainty:\n  wind_gust_prob: 1.5\n", "uncertainty.wind_gust_prob"),
    ("uncertainty:\n  takeoff_failure_prob: -0.1\n", "uncertainty.takeoff_failure_prob"),
    ("flight:\n  cruise_speed_mps: -3\n", "flight.cruise_speed_mps"),
    ("flight:\n  physics_rate_hz: 0\n", "flight.physics_rate_hz"),
    ("flight:\n  avoid_altitudes_m: [16, 12]\n", "flight.avoid_altitudes_m[1]"),
    ("battery:\n  initial_pct: 120\n", "battery.initial_pct"),
    ("schedule:\n  takeoff_after_landing_min: [20, 10]\n", "schedule.takeoff_after_landing_min"),
    ("layout:\n  normal_ports_xy_m: [[100, 0]]\n", "layout.normal_ports_xy_m[0]"),
    ("fleet_size: 20\n", "fleet_size"),
    ("atc:\n  skip_agents_without_decision: 1\n", "atc.skip_agents_without_decision"),
    ("- just\n- a list\n", "expected a mapping"),
    ("flight: [1, 2\n", "not valid YAML"),
])
def test_broken_configs_name_the_field(tmp_path, text, field):
    with pytest.raises(ConfigError, match=field.replace("[", r"\[").replace("]", r"\]")):
        load_config(write(tmp_path, text))


def test_unknown_config_name_lists_shipped_ones():
    with pytest.raises(ConfigError, match="paper_uncertain"):
        load_config("no_such_config")


def test_unknown_train_config_lists_the_ones_in_subfolders():
    from agents.training.config import load_train_config

    with pytest.raises(ConfigError, match="ppo_stage/long"):
        load_train_config("no_such_config")


def test_overrides_dotted_and_sections():
    cfg = load_config("paper", **{"uncertainty.wind_gust_prob": 0.2}, fleet_size=3)
    assert cfg.uncertainty.wind_gust_prob == 0.2 and cfg.fleet_size == 3
    cfg = load_config("paper", uncertainty={"charger_failure_prob": 0.3})
    assert cfg.uncertainty.charger_failure_prob == 0.3
    assert cfg.uncertainty.wind_gust_prob == 0.0
    with pytest.raises(ConfigError, match="uncertainty.wind_gust"):
        load_config("paper", **{"uncertainty.wind_gust": 0.2})
    with pytest.raises(ConfigError, match="uncertainty.wind_gust_prob"):
        load_config("paper", **{"uncertainty.wind_gust_prob": 2.0})


def test_base_key_extends_a_config(tmp_path):
    path = write(tmp_path, "base: paper\nfleet_size: 2\n")
    cfg = load_config(path)
    assert cfg.fleet_size == 2 and cfg.layout.hover_ring_count == 7
    loop = write(tmp_path, f"base: {tmp_path / 'cfg.yaml'}\n")
    with pytest.raises(ConfigError, match="includes itself"):
        load_config(loop)


def test_the_guide_lists_every_shipped_config():
    guide = (Path(__file__).resolve().parents[2] / "docs" / "configs.md").read_text()
    for path in ALL_CONFIGS:
        assert f"| `{path.stem}` |" in guide, f"docs/configs.md does not list configs/env/{path.name}"


@pytest.mark.parametrize("override, field", [
    ({"flight.cruise_speed_mps": float("inf")}, "flight.cruise_speed_mps"),
    ({"flight.flight_seconds_per_step": float("inf")}, "flight.flight_seconds_per_step"),
    ({"uncertainty.position_noise_mean_m": float("nan")}, "uncertainty.position_noise_mean_m"),
    ({"reward.term_magnitude": float("inf")}, "reward.term_magnitude"),
    ({"battery.charge_pct": float("-inf")}, "battery.charge_pct"),
])
def test_non_finite_numbers_are_refused_naming_the_field(override, field):
    with pytest.raises(ConfigError, match=f"^{re.escape(field)}: must be a finite number"):
        load_config("paper", **override)


def test_physics_rate_floor_ceiling_and_flag():
    with pytest.raises(ConfigError, match=r"^flight\.physics_rate_hz: must be >= 45 Hz .*allow_low"):
        load_config("paper", **{"flight.physics_rate_hz": 10})
    assert load_config("paper", **{"flight.physics_rate_hz": 10,
                                    "flight.allow_low_physics_rate": True}).flight.physics_rate_hz == 10
    with pytest.raises(ConfigError, match=r"^flight\.physics_rate_hz: must be <= 2000 Hz"):
        load_config("paper", **{"flight.physics_rate_hz": 1e9})


@pytest.mark.parametrize("override, field, words", [
    ({"layout.normal_ports_xy_m": [[-6.0, 0.0], [-5.5, 0.0]]}, "layout.normal_ports_xy_m[1]",
     "is 0.5 m from layout.normal_ports_xy_m[0]"),
    ({"layout.charging_ports_xy_m": [[6.0, 1.0]]}, "layout.charging_ports_xy_m[0]",
     "is 1 m from layout.normal_ports_xy_m[1]"),
    ({"layout.hover_spots_xy_m": [[10.0, 0.0], [10.0, 0.0]]}, "layout.hover_spots_xy_m[1]",
     "is 0 m from layout.hover_spots_xy_m[0]"),
    ({"layout.hover_ring_count": 40}, "layout.hover_ring_radius_m", "40 spots on a ring of 12 m"),
])
def test_pads_and_hover_spots_keep_a_vehicle_size_plus_the_separation(override, field, words):
    with pytest.raises(ConfigError, match=f"^{re.escape(field)}: {re.escape(words)}.*4 m"):
        load_config("paper", **override)


def test_unknown_keys_of_mixed_types_and_in_a_section_dict_are_named(tmp_path):
    path = tmp_path / "mixed.yaml"
    path.write_text("base: paper\n1: x\nfoo: y\n")
    with pytest.raises(ConfigError, match=r"1: unknown key"):
        load_config(path)
    with pytest.raises(ConfigError, match=r"^uncertainty\.wind_gust_probb: unknown key"):
        load_config("paper").replace(uncertainty={"wind_gust_probb": 0.1})
    with pytest.raises(ConfigError, match=r"^uncertainty\.wind_gust_probb: unknown key"):
        load_config("paper", uncertainty={"wind_gust_probb": 0.1})


def test_hover_and_transit_altitudes_must_be_off_the_ground():
    """Found by make fuzz: a 0.125 m hover altitude put hovering vehicles under a parked one's
    height."""
    for key in ("flight.hover_altitude_m", "flight.transit_altitude_m"):
        with pytest.raises(ConfigError, match=f"^{re.escape(key)}: must be above the vehicle's height"):
            load_config("paper", **{key: 0.125})


@pytest.mark.parametrize("key, value, words", [
    ("layout.destination_ring_count", 10**9, "must be <= 1000"),
    ("layout.hover_ring_count", 10**9, "must be <= 1000"),
    ("fleet_size", 10**9, "must lie in [1, 1000]"),
    ("flight.flight_seconds_per_step", 1e6, "engine substeps per step; at most 2000"),
])
def test_sizes_that_would_exhaust_memory_or_time_are_refused(key, value, words):
    """Found by make fuzz: a billion ring destinations took 24 GB before anything ran."""
    with pytest.raises(ConfigError, match=f"^{re.escape(key)}: .*{re.escape(words)}"):
        load_config("paper", **{key: value})


def test_a_step_too_short_to_move_is_refused():
    """Found by make fuzz: 1e-277 m/s for 3e-279 s per step divided by zero in the energy model."""
    with pytest.raises(ConfigError, match=r"^flight\.flight_seconds_per_step: .* at least 0\.01 m"):
        load_config("paper", **{"flight.cruise_speed_mps": 1e-277, "flight.flight_seconds_per_step": 3e-279})


def _make_aec(**kw):
    from marl_vertiport import vertiport_v1

    return vertiport_v1.env(config="paper", **kw)


def _make_gym(**kw):
    import gymnasium

    return gymnasium.make("marl_vertiport/Vertiport-v1", config="paper", **kw)


@pytest.mark.parametrize("make", [_make_aec, _make_gym], ids=["aec", "gymnasium"])
@pytest.mark.parametrize("keyword, shown, known", [
    ("fleet_sise", "fleet_sise: unknown key", "known: atc, battery, fleet_size, flight"),
    ("uncertainty.wind_gust_prb", "uncertainty.wind_gust_prb: unknown key",
     "known: action_misread_prob, charger_failure_prob"),
    ("uncertainty__wind_gust_prb", "uncertainty.wind_gust_prb: unknown key",
     "known: action_misread_prob, charger_failure_prob"),
    ("uncertanty__wind_gust_prob", "uncertanty: unknown config section",
     "sections: atc, battery, flight, layout"),
])
def test_unknown_env_keywords_are_config_errors_and_type_errors(make, keyword, shown, known):
    """Python's and Gymnasium's convention (a ``TypeError`` saying "unexpected keyword
    argument", which TorchRL's GymEnv relies on) and the env's own (``ConfigError``)."""
    with pytest.raises(ConfigError) as exc:
        make(**{keyword: 1})
    assert isinstance(exc.value, TypeError)
    message = str(exc.value)
    assert f"got an unexpected keyword argument {keyword!r}" in message
    assert shown in message and known in message


def test_config_typos_in_a_file_or_an_override_keep_their_field_errors(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text("base: paper\nfleet_sise: 4\n")
    with pytest.raises(ConfigError, match=r"fleet_sise: unknown key \(known: atc, battery") as exc:
        load_config(path)
    assert not isinstance(exc.value, TypeError)
    with pytest.raises(ConfigError, match=r"^fleet_sise: unknown key \(known: atc") as exc:
        load_config("paper", fleet_sise=4)
    assert "unexpected keyword" not in str(exc.value)
    # A bad value of a known key stays a plain field error, not a TypeError.
    from marl_vertiport import vertiport_v1

    with pytest.raises(ConfigError, match=r"uncertainty.wind_gust_prob: is a probability") as exc:
        vertiport_v1.env(config="paper", **{"uncertainty.wind_gust_prob": 1.5})
    assert not isinstance(exc.value, TypeError)


def test_set_typos_in_the_evaluation_name_the_field(tmp_path, capsys):
    from agents.evaluate.cli import main

    assert main(["--agents", "fcfs", "--episodes", "1", "--set", "fleet_sise=4",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "fleet_sise: unknown key (known: atc, battery, fleet_size" in err
    assert "unexpected keyword" not in err


def test_a_separation_wider_than_hover_spots_stand_from_pads_is_a_named_error():
    # Paper layout at 9 m: a vehicle hovering over a ring spot is 8 m from one parked on port 1.
    with pytest.raises(ConfigError, match=r"^layout.hover_ring_radius_m: .*safety.min_separation_m = 9 m"):
        load_config("paper", **{"safety.min_separation_m": 9.0})
    with pytest.raises(ConfigError, match=r"^layout.hover_spots_xy_m\[0\]"):
        load_config("paper", **{"safety.min_separation_m": 5.0, "layout.hover_spots_xy_m": [[6.0, 1.0]]})
