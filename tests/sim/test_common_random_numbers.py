"""Common random numbers (``uncertainty.common_random_numbers``): the luck of a day after its
first state is keyed by what each draw is for, so controllers that decide differently meet the
same charger failures step by step, the same outcome of each vehicle's k-th take-off and the
same k-th flight plan; a restored sim replays the same future; a look-ahead's rollouts key
streams of their own and do not see the env's."""

import numpy as np
import pytest

from helpers import busy_action
from marl_vertiport.config import load_config
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.spaces import ObservationBuilder

STEPS = 1440  # the whole day


def _day(common: bool, agent: str) -> dict:
    """A day of ``paper`` at 20 % uncertainty flown by ``agent`` (a controller spec); what luck
    gave it."""
    from agents.controllers.registry import make_controller

    cfg = load_config("paper_uncertain_10", **{
        "uncertainty.common_random_numbers": common, "uncertainty.wind_gust_prob": 0.2,
        "uncertainty.charger_failure_prob": 0.2, "uncertainty.takeoff_failure_prob": 0.2})
    sim = VertiportSim(cfg)
    sim.reset(np.random.default_rng(11))
    builder = ObservationBuilder(sim)
    controller = make_controller(agent)
    chargers, attempts = [], [[] for _ in range(sim.n)]
    for _ in range(STEPS):
        v = sim.acting
        obs = builder.observe(v)
        _, info = sim.step(controller.act(obs))
        chargers.append(info["charger_failures"])
        if info["takeoff"] or info["takeoff_failed"]:
            attempts[v].append(info["takeoff_failed"])
    sim.close()
    return {"chargers": chargers, "attempts": attempts}


def test_two_controllers_meet_the_same_luck_only_with_common_random_numbers():
    a, b = _day(True, "dispatcher"), _day(True, "fcfs")
    assert a["chargers"] == b["chargers"]  # step t's charger failures, whoever flies
    compared = 0
    for x, y in zip(a["attempts"], b["attempts"]):
        k = min(len(x), len(y))
        assert x[:k] == y[:k]  # a vehicle's k-th take-off fails under both or neither
        compared += k
    assert compared >= 10 and any(any(x) for x in a["attempts"])
    # One generator for everything: the two days' luck parts once their decisions do.
    c, d = _day(False, "dispatcher"), _day(False, "fcfs")
    assert c["chargers"] != d["chargers"]


def test_common_random_numbers_keep_the_first_state_and_off_changes_nothing():
    def first(common: bool) -> tuple:
        sim = VertiportSim(load_config("paper_uncertain_10",
                                       **{"uncertainty.common_random_numbers": common}))
        sim.reset(np.random.default_rng(3))
        state = (sim.status.copy(), sim.pending_time.copy(), sim.dest.copy(), sim.node.copy())
        sim.close()
        return state

    for x, y in zip(first(True), first(False)):
        np.testing.assert_array_equal(x, y)


def test_restore_replays_the_keyed_future_and_a_new_generator_draws_another():
    cfg = load_config("paper_uncertain_10", **{
        "uncertainty.common_random_numbers": True, "uncertainty.charger_failure_prob": 0.3,
        "uncertainty.position_noise_std_m": 1.0})
    sim = VertiportSim(cfg)
    sim.reset(np.random.default_rng(7))
    builder = ObservationBuilder(sim)

    def run(steps: int) -> list:
        rng = np.random.default_rng(1)
        out = []
        for _ in range(steps):
            _, info = sim.step(busy_action(builder.observe(sim.acting), rng))
            out.append((info["charger_failures"], info["gusts"], sim.battery.tolist(),
                        sim.obs_xy.tolist()))
        return out

    run(200)
    snap = sim.snapshot()
    first = run(150)
    sim.restore(snap)
    assert run(150) == first
    # A look-ahead's own future (agents.controllers.planner.roll_out): other streams.
    sim.restore(snap)
    sim.use_generator(np.random.default_rng(123))
    assert [s[0] for s in run(150)] != [s[0] for s in first]
    sim.close()


@pytest.mark.parametrize("common", [False, True])
def test_the_guard_is_not_clairvoyant_with_common_random_numbers(common):
    """The guard's rollouts draw from generators of their own: with keyed streams as without,
    a rollout of the env's state does not replay the env's future."""
    from agents.controllers.planner import roll_out
    from agents.controllers.registry import make_controller

    cfg = load_config("paper_uncertain_10", **{"uncertainty.common_random_numbers": common,
                                               "uncertainty.charger_failure_prob": 0.5})
    sim, scratch = VertiportSim(cfg), VertiportSim(cfg)
    sim.reset(np.random.default_rng(4))
    builder, scratch_builder = ObservationBuilder(sim), ObservationBuilder(scratch)
    fleet = make_controller("dispatcher")
    snap = sim.snapshot()
    seen = []

    def watch(s):
        seen.append(s.last_info["charger_failures"])

    action = fleet.act(builder.observe(sim.acting))
    roll_out(scratch, scratch_builder, fleet, snap, action, 60, np.random.default_rng(9), watch)
    env_future = []
    sim.step(action)
    env_future.append(sim.last_info["charger_failures"])
    for _ in range(59):
        sim.step(fleet.act(builder.observe(sim.acting)))
        env_future.append(sim.last_info["charger_failures"])
    assert seen != env_future
    sim.close()
    scratch.close()
