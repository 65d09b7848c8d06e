"""The look-ahead planner: it leaves the real env untouched, takes only legal actions, values
the horizon's end as documented, and beats the dispatcher it rolls out."""

import math

import numpy as np
import pytest

from agents.controllers.episode import run_gym_episode
from agents.controllers.dispatcher import DispatcherController
from agents.controllers.registry import make_controller
from agents.controllers.planner import PlannerController
from helpers import seed0_sim
from marl_vertiport import vertiport_v1
from marl_vertiport.gym_env import VertiportEnv
from marl_vertiport.sim.schema import OUT_OF_SERVICE
from marl_vertiport.spaces import ObservationBuilder


def test_planning_leaves_the_env_untouched_and_acts_legally():
    env = VertiportEnv("paper")
    obs, _ = env.reset(seed=4)
    planner = PlannerController(horizon=6)
    planner.bind(env.sim)
    for _ in range(120):
        before = env.sim.snapshot()
        action = planner.act(obs)
        assert obs["action_mask"][action] == 1
        after = env.sim.snapshot()
        for key in ("pos", "battery", "status", "node_occupant", "pending_time"):
            np.testing.assert_array_equal(before[key], after[key])
        assert before["rng"].bit_generator.state == after["rng"].bit_generator.state
        obs, *_ = env.step(action)
    env.close()
    planner.close()


def test_candidates_and_unbound_use():
    sim = seed0_sim()  # evtol_0 on the charger (100 %), evtol_3 hovering
    planner = PlannerController(horizon=3, min_takeoff_battery_pct=80.0)
    planner.bind(sim)
    assert sim.acting == 0
    assert planner.candidates(sim) == [0, 1]  # stay, take off (both normal ports are taken)
    sim.battery[0] = 50.0
    assert planner.candidates(sim) == [0]  # too little charge to be worth a take-off candidate
    assert set(planner.q_values(sim)) == {0}
    sim.acting = 3  # hovering: stay or land on a free port
    sim.node_occupant[0], sim.node[2] = -1, -1  # free normal port 0 for the test
    assert planner.candidates(sim) == [0, 2] and not planner.last_forced
    sim.battery[3] = 20.0  # at the reserve: staying aloft is ruled out
    assert planner.candidates(sim) == [2] and planner.last_forced
    with pytest.raises(RuntimeError, match="bind"):
        PlannerController().act({"action_mask": np.ones(14, np.int8)})
    with pytest.raises(ValueError, match="horizon"):
        PlannerController(horizon=0)
    assert make_controller("planner").name == "planner"
    planner.close()


class _AskedEveryTurn(DispatcherController):
    """The dispatcher without the claim that its act is pure: a planner must ask it every turn."""

    pure_act = False

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def act(self, observation: dict) -> int:
        self.calls += 1
        return super().act(observation)


def test_planning_shortcuts_change_no_decision_or_value():
    """A decision with one candidate is not simulated, and rollout turns with one legal action
    skip a pure base controller: the actions and values are those of asking it every turn."""
    env = VertiportEnv("paper")
    fast, slow = PlannerController(horizon=8), PlannerController(horizon=8, rollout_policy=_AskedEveryTurn())
    obs, _ = env.reset(seed=6)
    fast.bind(env.sim)
    slow.bind(env.sim)
    skipped = 0
    for _ in range(160):
        calls = slow.rollout_policy.calls
        action = fast.act(obs)
        assert slow.act(obs) == action
        if len(slow.last_q) > 1:
            assert fast.last_q == slow.last_q
        else:
            skipped += 1
            assert fast.last_q == {}
            assert slow.rollout_policy.calls - calls == 1  # only its own choice: nothing was simulated
        obs, *_ = env.step(action)
    assert skipped > 0 and slow.rollout_policy.calls > 160
    env.close()
    fast.close()
    slow.close()


def test_terminal_value_by_hand():
    sim = seed0_sim()
    planner = PlannerController(terminal_turns=10)
    sim.battery[:] = [100.0, 50.0, 20.0, 0.0]
    sim.delay[:] = [0.0, 0.0, 3.0, 0.0]
    sim.status[3] = OUT_OF_SERVICE
    # Per turn: battery term 0.35 * (5 + 2.5 - 5 - 5), delay term 0.1 * (5 + 5 + (-5 + 10 e^-3) - 5).
    per_turn = 0.35 * (5.0 + 2.5 - 5.0 - 5.0) + 0.1 * (5.0 + 5.0 - 5.0 + 10.0 * math.exp(-3.0) - 5.0)
    assert planner.terminal_value(sim) == pytest.approx(10 * per_turn)
    sim.step_count = sim.cfg.schedule.episode_steps - 8  # 2 turns of each vehicle left
    assert planner.terminal_value(sim) == pytest.approx(2 * per_turn)
    assert PlannerController(terminal_turns=0).terminal_value(sim) == 0.0


def test_planner_beats_the_dispatcher_it_rolls_out():
    # The paper's ATC (no energy check): the planner finds, among other things, that flying a
    # vehicle stranded at 0 % into an emergency landing stops its delay from growing. With the
    # energy check on, its lead over the dispatcher on half a day is within the day-to-day noise.
    env = VertiportEnv("paper", **{"schedule.episode_steps": 480, "atc.energy_check": False})
    totals = {}
    for name, ctl in (("dispatcher", DispatcherController()), ("planner", PlannerController())):
        totals[name] = sum(run_gym_episode(env, ctl, seed)["total_reward"] for seed in (11, 12))
    env.close()
    assert totals["planner"] > totals["dispatcher"] + 100.0


def test_rollouts_run_on_the_nominal_model_unless_asked_otherwise():
    env = vertiport_v1.env(config="paper_uncertain")
    env.reset(seed=3)
    sim = env.unwrapped.sim
    assert sim.cfg.uncertainty.wind_gust_prob > 0  # the premise: the env has uncertainties
    nominal, noisy = PlannerController(horizon=2), PlannerController(horizon=2, nominal=False)
    nominal.bind(sim)
    noisy.bind(sim)
    un = nominal._scratch.cfg.uncertainty
    assert un.wind_gust_prob == un.charger_failure_prob == un.takeoff_failure_prob == 0.0
    assert nominal._scratch.cfg.layout == sim.cfg.layout
    assert noisy._scratch.cfg == sim.cfg
    obs = env.observe(env.agent_selection)
    assert obs["action_mask"][nominal.act(obs)]  # plans on a copy of another config
    nominal.close()
    noisy.close()
    env.close()


def test_a_failed_takeoff_steps_as_a_stay():
    # The premise of expect_failures: the failure branch of a take-off is the stay's rollout.
    sim = seed0_sim(rules=1, **{"uncertainty.takeoff_failure_prob": 1.0})
    assert sim.acting == 0 and sim.action_mask(0)[sim.actions.takeoff]
    snap = sim.snapshot()
    failed, info = sim.step(sim.actions.takeoff)
    assert info["takeoff_failed"]
    after_failure = sim.snapshot()
    sim.restore(snap)
    stayed, _ = sim.step(sim.actions.stay)
    assert failed == stayed
    for key in ("pos", "battery", "status", "node", "node_occupant", "pending_time", "delay"):
        np.testing.assert_array_equal(after_failure[key], sim.snapshot()[key])


def test_expect_failures_weighs_a_takeoff_by_its_failure():
    env = vertiport_v1.env(config="paper_uncertain")
    env.reset(seed=5)
    sim = env.unwrapped.sim
    p = sim.cfg.uncertainty.takeoff_failure_prob
    assert p > 0  # the premise: take-offs can fail in this config
    plain, weighed = PlannerController(horizon=8), PlannerController(horizon=8, expect_failures=True)
    plain.bind(sim)
    weighed.bind(sim)
    dispatcher, compared = DispatcherController(), 0
    dispatcher.bind(sim)
    takeoff, stay = sim.actions.takeoff, sim.actions.stay
    for _ in range(200):
        obs = env.observe(env.agent_selection)
        plain.act(obs)
        weighed.act(obs)
        if takeoff in plain.last_q:
            q, w = plain.last_q, weighed.last_q
            assert w[takeoff] == pytest.approx((1 - p) * q[takeoff] + p * q[stay])
            assert {a: v for a, v in w.items() if a != takeoff} == {
                a: v for a, v in q.items() if a != takeoff}
            compared += 1
        env.step(dispatcher.act(obs))
    assert compared >= 5
    with pytest.raises(ValueError, match="nominal"):
        PlannerController(nominal=False, expect_failures=True)
    for planner in (plain, weighed):
        planner.close()
    env.close()


def test_rescue_simulates_the_filtered_actions_when_every_candidate_loses_a_vehicle():
    # evtol_1 on a normal port at 20 %, the charger taken: too little charge for a take-off
    # candidate, and the dispatcher stays, which idles it to empty within the horizon.
    sim = seed0_sim(rules=1)
    sim.acting, sim.battery[1] = 1, 20.0
    obs = ObservationBuilder(sim).observe(1)
    plain, rescuer = PlannerController(), PlannerController(rescue=True)
    plain.bind(sim)
    rescuer.bind(sim)
    assert plain.act(obs) == sim.actions.stay and plain.last_q == {}  # unsimulated
    assert rescuer.act(obs) == sim.actions.takeoff
    assert rescuer.last_q[sim.actions.stay] < -500 < 0 < rescuer.last_q[sim.actions.takeoff]
    sim.battery[1] = 40.0  # staying keeps the fleet: nothing left out is simulated
    obs = ObservationBuilder(sim).observe(1)
    assert rescuer.act(obs) == plain.act(obs) and rescuer.last_q == plain.last_q
    plain.close()
    rescuer.close()
