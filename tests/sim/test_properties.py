"""Property-based tests (hypothesis): configs generated from the schema itself, any legal action
sequence, any illegal action, snapshot and restore at any step.

The default profile keeps ``make test`` quick; ``make fuzz`` (``HYPOTHESIS_PROFILE=long``) runs
the same properties on many more examples."""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import typing

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from marl_vertiport.config import ConfigError, EnvConfig, load_config
from marl_vertiport.sim.core import IllegalActionError, VertiportSim
from marl_vertiport.sim.invariants import violations

settings.register_profile("default", max_examples=25, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=1500, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

def schema_fields(cls: type = EnvConfig, prefix: str = "") -> list[tuple[str, typing.Any, typing.Any]]:
    """Every leaf of the schema: ``(dotted key, type, default)``, read from the dataclasses."""
    out = []
    hints = typing.get_type_hints(cls)
    default = cls()
    for f in dataclasses.fields(cls):
        tp, value = hints[f.name], getattr(default, f.name)
        if dataclasses.is_dataclass(tp):
            out += schema_fields(tp, f"{prefix}{f.name}.")
        else:
            out.append((f"{prefix}{f.name}", tp, value))
    return out


# Coordinates and names are left to the hand-written tests; everything else is generated.
FIELDS = [f for f in schema_fields() if f[0] != "name" and not f[0].endswith("_xy_m")]
SPECIAL = [0.0, -1.0, math.inf, -math.inf, math.nan, 1e9, 1e-9]


def value_for(tp: typing.Any, default: typing.Any) -> st.SearchStrategy:
    """Values near the default (mostly valid), and edge values (mostly not)."""
    if tp is bool:
        return st.booleans()
    if tp is int:
        return st.one_of(st.integers(-3, 3 * max(int(default), 1) + 3), st.sampled_from([-1, 0, 10**9]))
    if tp is float:
        near = st.floats(0.0, 3.0).map(lambda s: default * s if default else s)
        return st.one_of(near, near, st.sampled_from(SPECIAL), st.floats(-100, 100))
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        inner = args[0]
        size = len(default) if args[-1] is not Ellipsis else None
        item = value_for(inner, default[0] if default else 1.0)
        if size is not None:
            return st.lists(item, min_size=size, max_size=size).map(tuple)
        return st.lists(item, min_size=0, max_size=4).map(tuple)
    return st.just(default)


@st.composite
def overrides(draw) -> dict[str, typing.Any]:
    picked = draw(st.lists(st.sampled_from(FIELDS), min_size=1, max_size=3, unique_by=lambda f: f[0]))
    return {key: draw(value_for(tp, default)) for key, tp, default in picked}


def play(sim: VertiportSim, choices: list[int]) -> list:
    """Legal actions picked by ``choices`` (each an index into the legal ones); the trace."""
    trace = []
    for c in choices:
        legal = np.flatnonzero(sim.action_mask(sim.acting))
        reward, info = sim.step(int(legal[c % len(legal)]))
        assert not violations(sim, reward), violations(sim, reward)
        trace.append((reward, sim.pos.copy(), sim.battery.copy(), sim.status.copy()))
    return trace


@given(over=overrides(), seed=st.integers(0, 2**16))
def test_generated_configs_load_with_a_named_error_or_run_keeping_every_invariant(over, seed):
    try:
        cfg = load_config("paper", **over)
    except ConfigError as exc:
        # The error names a field of the schema (the dotted key before the first colon).
        field = str(exc).split(":")[0].split("[")[0]
        assert any(field == key or key.startswith(field + ".") or field.startswith(key)
                   for key, _, _ in schema_fields()), str(exc)
        return
    sim = VertiportSim(cfg)
    try:
        sim.reset(np.random.default_rng(seed))
        rng = np.random.default_rng(seed)
        play(sim, rng.integers(0, 1000, size=min(30, cfg.schedule.episode_steps)).tolist())
    finally:
        sim.close()


CONFIGS = ["paper", "paper_uncertain", "small", "mid"]
HIGH = {"uncertainty.wind_gust_prob": 0.3, "uncertainty.charger_failure_prob": 0.3,
        "uncertainty.takeoff_failure_prob": 0.3, "uncertainty.action_misread_prob": 0.1,
        "uncertainty.position_noise_std_m": 1.0}


@pytest.fixture(scope="module")
def sims():
    made = {(c, high): VertiportSim(load_config(c, **(HIGH if high else {})))
            for c in CONFIGS for high in (False, True)}
    yield made
    for sim in made.values():
        sim.close()


@given(config=st.sampled_from(CONFIGS), high=st.booleans(), seed=st.integers(0, 2**16),
       choices=st.lists(st.integers(0, 10**6), min_size=1, max_size=120))
def test_any_legal_sequence_keeps_the_invariants(sims, config, high, seed, choices):
    sim = sims[(config, high)]
    sim.reset(np.random.default_rng(seed))
    play(sim, choices)


@given(config=st.sampled_from(CONFIGS), seed=st.integers(0, 2**16),
       choices=st.lists(st.integers(0, 10**6), max_size=60),
       bad=st.one_of(st.integers(-5, 60), st.floats(allow_nan=True), st.text(max_size=2),
                     st.none(), st.booleans()))
def test_an_illegal_action_raises_and_changes_nothing(sims, config, seed, choices, bad):
    sim = sims[(config, True)]
    sim.reset(np.random.default_rng(seed))
    play(sim, choices)
    if isinstance(bad, int) and not isinstance(bad, bool) and 0 <= bad < sim.actions.n \
            and sim.action_mask(sim.acting)[bad]:
        return  # legal after all
    before = sim.snapshot()
    rng_state = copy.deepcopy(sim.rng.bit_generator.state)
    with pytest.raises(IllegalActionError):
        sim.step(bad)
    assert sim.rng.bit_generator.state == rng_state
    after = sim.snapshot()
    for key, value in before.items():
        if key == "_physics":
            continue
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, after[key], err_msg=key)


@given(config=st.sampled_from(CONFIGS), seed=st.integers(0, 2**16),
       first=st.lists(st.integers(0, 10**6), max_size=80),
       then=st.lists(st.integers(0, 10**6), min_size=1, max_size=60))
def test_restore_at_any_step_replays_identically(sims, config, seed, first, then):
    sim = sims[(config, True)]
    sim.reset(np.random.default_rng(seed))
    play(sim, first)
    snap = sim.snapshot()
    a = play(sim, then)
    sim.restore(snap)
    b = play(sim, then)
    for x, y in zip(a, b):
        assert x[0] == y[0]
        for u, w in zip(x[1:], y[1:]):
            np.testing.assert_array_equal(u, w)
