"""The guard's rollouts: what they draw. Clairvoyant rollouts draw the env's own future; a
full comparison may draw more rollouts than a check, its first ones those of the check."""

import numpy as np
import pytest

from agents.controllers.dispatcher import DispatcherController
from agents.controllers.episode import run_episode
from agents.controllers.guard import GuardController
from agents.controllers.registry import make_controller
from marl_vertiport import vertiport_v1


def test_clairvoyant_rollouts_are_the_days_actual_future():
    """With ``clairvoyant`` the rollout of the base's choice draws the env's own future: after
    the same 60 steps of the base, the scratch simulator and the env are in the same state."""
    env = vertiport_v1.env(config="paper_uncertain_10")
    env.reset(seed=800001)
    sim = env.unwrapped.sim
    guard = GuardController(clairvoyant=True, horizon_min=60)
    guard.reset(seed=800001)
    guard.bind(sim)
    assert guard._runs == 1
    base = DispatcherController()
    base.bind(sim)
    for _ in range(100):
        env.step(base.act(env.observe(env.agent_selection)))
    action = base.act(env.observe(env.agent_selection))
    guard.evaluate(sim, [action])
    for _ in range(60):
        env.step(action)
        action = base.act(env.observe(env.agent_selection))
    scratch = guard._scratch
    for key in ("pos", "battery", "status"):
        np.testing.assert_array_equal(getattr(scratch, key), getattr(sim, key))
    assert scratch.metrics.failed_takeoffs == sim.metrics.failed_takeoffs
    assert scratch.rng.bit_generator.state == sim.rng.bit_generator.state
    guard.close()
    env.close()


def test_clairvoyant_guard_changes_only_the_base_days_that_lose_a_vehicle():
    """Its rollouts of the base's choice are the base's actual day: where that loses no vehicle,
    it changes nothing, and the day is the base's, metric for metric; where it does, it finds
    the decision to change."""
    env = vertiport_v1.env(config="paper_uncertain_10", **{"schedule.episode_steps": 300})
    base = run_episode(env, make_controller("dispatcher"), seed=800001)
    guard = GuardController(clairvoyant=True)
    seen = run_episode(env, guard, seed=800001)
    env.close()
    assert base["stranded"] == 0 and base["failed_takeoffs"] > 0  # a day with failures
    assert guard.checks > 0 and guard.changes == 0
    assert seen == base
    guard.close()
    # Validation day 800029 at 10 %, its first 8 hours: the base loses two vehicles, and one
    # decision changed with the day's future in view keeps them.
    env = vertiport_v1.env(config="paper_uncertain_10", **{"schedule.episode_steps": 480})
    base = run_episode(env, make_controller("dispatcher"), seed=800029)
    guard = GuardController(clairvoyant=True)
    seen = run_episode(env, guard, seed=800029)
    env.close()
    assert base["stranded"] >= 2 and seen["stranded"] == 0 and guard.changes == 1
    guard.close()


def test_compare_samples_draws_more_rollouts_only_where_every_action_is_compared():
    """``compare_samples`` sets the rollouts per action of the full comparison (at least
    ``samples``; ``samples`` by default, one where all rollouts are alike); the comparison's
    first ``samples`` rollouts draw what the check drew, so its values over those are the
    check's."""
    with pytest.raises(ValueError, match="compare_samples"):
        GuardController(samples=4, compare_samples=3)
    assert GuardController(samples=3).compare_samples == 3
    assert make_controller("lookahead[compare_samples=16]").compare_samples == 16
    for config, runs in (("paper", (1, 1)), ("paper_uncertain", (4, 6))):
        env = vertiport_v1.env(config=config)
        guard = GuardController(samples=4, compare_samples=6)
        guard.bind(env.unwrapped.sim)
        assert (guard._runs, guard._compare_runs) == runs
        guard.close()
        env.close()
    env = vertiport_v1.env(config="paper_uncertain_10")
    env.reset(seed=0)
    sim = env.unwrapped.sim
    guard = GuardController(samples=2, compare_samples=5)
    guard.reset(seed=0)
    guard.bind(sim)
    action = int(np.flatnonzero(env.observe(env.agent_selection)["action_mask"])[0])
    few, _ = guard.evaluate(sim, [action])
    many, _ = guard.evaluate(sim, [action], runs=5)
    per_run = [guard.evaluate(sim, [action], runs=k)[0][action][1] * k for k in (1, 2, 5)]
    assert few[action][1] == pytest.approx(per_run[1] / 2)  # the check's 2 draws come first
    assert many[action][1] == pytest.approx(per_run[2] / 5)
    assert per_run[2] != pytest.approx(5 * per_run[0])  # the later draws differ
    guard.close()
    env.close()
