"""Invariants over long runs, determinism, and illegal actions through the AEC API."""

import numpy as np
import pytest

from helpers import busy_action
from marl_vertiport import IllegalActionError, vertiport_v1
from marl_vertiport.sim.invariants import violations


def run_day(config: str, seed: int, policy: str, check=None, **overrides) -> list:
    """Run one AEC day; return the per-step (agent, action, reward) trace."""
    env = vertiport_v1.env(config=config, **overrides)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed + 1)
    trace = []
    for agent in env.agent_iter():
        obs, _, term, trunc, _ = env.last()
        if term or trunc:
            env.step(None)
            continue
        if policy == "random":
            action = int(rng.choice(np.flatnonzero(obs["action_mask"])))
        else:
            action = busy_action(obs, rng)
        env.step(action)
        trace.append((agent, action, env.rewards[agent], env.unwrapped.sim.pos.copy()))
        if check is not None:
            check(env.unwrapped.sim, obs)
    return trace


def check_invariants(sim, obs) -> None:
    """The simulator's one invariant checker (marl_vertiport/sim/invariants.py), after a step."""
    found = violations(sim)
    assert not found, found
    assert obs["action_mask"].sum() >= 1


@pytest.mark.slow
@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
@pytest.mark.parametrize("policy", ["random", "busy"])
def test_invariants_over_long_runs(config, policy):
    for seed in range(2):
        trace = run_day(config, seed, policy, check=check_invariants)
        assert len(trace) == 1440


def test_time_advances_one_minute_per_step():
    env = vertiport_v1.env()
    env.reset(seed=0)
    sim = env.unwrapped.sim
    for t in range(50):
        assert sim.minute == t
        obs, *_ = env.last()
        env.step(int(np.flatnonzero(obs["action_mask"])[0]))
    assert sim.minute == 50


@pytest.mark.slow
@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
def test_same_seed_same_actions_bit_identical(config):
    overrides = {}
    if config == "paper_uncertain":  # every randomised effect on, observation noise included
        overrides = {"uncertainty.position_noise_mean_m": 1.0, "uncertainty.position_noise_std_m": 1.0,
                     "uncertainty.action_misread_prob": 0.05}
    a = run_day(config, 11, "busy", **overrides)
    b = run_day(config, 11, "busy", **overrides)
    for (ag1, act1, r1, p1), (ag2, act2, r2, p2) in zip(a, b):
        assert (ag1, act1) == (ag2, act2)
        assert r1 == r2  # bit-identical, not approximately equal
        assert np.array_equal(p1, p2)
    c = run_day(config, 12, "busy", **overrides)
    assert any(r1 != r3 for (_, _, r1, _), (_, _, r3, _) in zip(a, c))


def test_reset_without_seed_continues_the_generator():
    env = vertiport_v1.env(config="paper_uncertain")
    env.reset(seed=5)
    first = env.unwrapped.sim.pending_time.copy()
    rng = env.unwrapped.sim.rng
    state = rng.bit_generator.state
    env.reset()
    # The same generator goes on (not reseeded, not replaced) ...
    assert env.unwrapped.sim.rng is rng and rng.bit_generator.state != state
    # ... and a seeded reset reproduces the seeded start.
    env.reset(seed=5)
    assert np.array_equal(env.unwrapped.sim.pending_time, first)


@pytest.mark.parametrize("bad", [99, -1, 2.0, "takeoff", None, np.float32(1.0)])
def test_illegal_action_through_the_aec_api_changes_nothing(bad):
    env = vertiport_v1.env()
    env.reset(seed=2)
    sim = env.unwrapped.sim
    agent = env.agent_selection
    obs_before = env.observe(agent)
    snapshot = (sim.pos.copy(), sim.battery.copy(), sim.minute, sim.status.copy(),
                sim.node_occupant.copy(), sim.rng.bit_generator.state)
    with pytest.raises(ValueError, match=agent) as err:
        env.step(bad)
    assert "legal" in str(err.value)
    assert isinstance(err.value, IllegalActionError)
    assert env.agent_selection == agent
    np.testing.assert_array_equal(sim.pos, snapshot[0])
    np.testing.assert_array_equal(sim.battery, snapshot[1])
    assert sim.minute == snapshot[2]
    np.testing.assert_array_equal(sim.status, snapshot[3])
    np.testing.assert_array_equal(sim.node_occupant, snapshot[4])
    assert sim.rng.bit_generator.state == snapshot[5]
    obs_after = env.observe(agent)
    np.testing.assert_array_equal(obs_before["action_mask"], obs_after["action_mask"])
    # The env is still usable afterwards.
    env.step(int(np.flatnonzero(obs_after["action_mask"])[0]))
    assert sim.minute == 1


def test_masked_out_action_names_the_legal_set():
    env = vertiport_v1.env()
    env.reset(seed=2)
    obs = env.observe(env.agent_selection)
    illegal = int(np.flatnonzero(obs["action_mask"] == 0)[0])
    with pytest.raises(ValueError, match=r"masked out.*legal actions now"):
        env.step(illegal)


def test_episode_summary_has_exactly_the_registered_metrics_in_order():
    """One source for the metric list: the summary, the evaluation's labels and the training
    logs all follow marl_vertiport.sim.metrics.METRICS (the evaluation's labels add the
    metrics it derives across agents and the per-episode names it gives a metric of the
    simulator, ``vehicles_lost`` for ``stranded``)."""
    from agents.evaluate.metrics import (
        DERIVED_METRICS, DIRECTION, EPISODE_ALIASES, METRIC_LABELS, with_aliases,
    )
    from agents.training.curves import CURVE_KEYS
    from agents.training.vec_env import LOGGED_METRICS
    from marl_vertiport import vertiport_v1
    from marl_vertiport.sim.metrics import METRICS, TRAINING_METRICS

    env = vertiport_v1.env(config="small", schedule__episode_steps=20)
    env.reset(seed=0)
    summary = env.unwrapped.sim.episode_metrics()
    assert list(summary) == [*METRICS, "action_counts"]
    assert list(METRIC_LABELS) == [*METRICS, *EPISODE_ALIASES, *DERIVED_METRICS]
    assert not set(DERIVED_METRICS) & set(summary)
    assert set(EPISODE_ALIASES.values()) <= set(METRICS) and not set(EPISODE_ALIASES) & set(METRICS)
    aliased = with_aliases(summary)
    assert all(aliased[alias] == summary[of] for alias, of in EPISODE_ALIASES.items())
    assert set(DIRECTION) <= set(METRICS) | set(EPISODE_ALIASES)
    assert all(v in (-1, 1) for v in DIRECTION.values())
    assert LOGGED_METRICS == TRAINING_METRICS == CURVE_KEYS[-len(TRAINING_METRICS):]
    assert {"total_reward", "stranded", "collisions"} <= set(TRAINING_METRICS)


def test_the_invariant_checker_sees_each_kind_of_breakage():
    import numpy as np

    from marl_vertiport.config import load_config
    from marl_vertiport.sim.core import VertiportSim
    from marl_vertiport.sim.invariants import violations

    sim = VertiportSim(load_config("paper"))
    sim.reset(np.random.default_rng(0))
    assert violations(sim, 1.0) == []
    assert violations(sim, 7.5)[0].startswith("reward 7.5 outside")
    sim.battery[0] = 101.0
    sim.pos[1, 2] = -1.0
    found = " | ".join(violations(sim))
    assert "evtol_0: battery 101.0" in found and "evtol_1: below the ground" in found
    sim.close()
