"""Flight physics in pybullet: commanded speed, measured separation, engine contacts, and an
"avoid collision" that really keeps vehicles apart."""

import numpy as np
import pytest

from marl_vertiport.config import load_config
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import ARRIVING, HOVERING, TAXIING

# Six hover spots on the axes, 10-14 m from the centre (at least 4 m apart); two vehicles.
SPOTS = [[-10.0, 0.0], [10.0, 0.0], [0.0, -10.0], [0.0, 10.0], [14.0, 0.0], [-14.0, 0.0]]


def make_sim(**overrides) -> VertiportSim:
    cfg = load_config("paper", fleet_size=2, **{"layout.hover_spots_xy_m": SPOTS}, **overrides)
    sim = VertiportSim(cfg)
    sim.reset(np.random.default_rng(0))
    return sim


def hover_at(sim: VertiportSim, v: int, spot: int) -> None:
    """Put vehicle ``v`` at hover spot ``spot`` (index among hover spots), waiting to land."""
    node = sim.layout.n_ports + spot
    sim._release(v)
    sim._occupy(v, node)
    sim.status[v] = HOVERING
    sim.pos[v] = sim._node_pos[node]
    sim.physics.make_static(v, sim.pos[v])
    sim.pending_kind[v] = 2
    sim.pending_time[v] = sim.minute + 15
    sim._mask_cache = {}
    sim._evtol_cache = None


def spot_action(sim: VertiportSim, spot: int) -> int:
    return sim.actions.node_action(sim.layout.n_ports + spot)


def test_vehicle_flies_at_the_commanded_speed_in_the_engine():
    sim = make_sim()
    hover_at(sim, 0, 0)
    hover_at(sim, 1, 3)
    assert sim.acting == 0
    sim.step(spot_action(sim, 1))  # (-10, 0) -> (10, 0), 20 m at 4 m altitude
    # 8 m/s for 0.25 s of flight: 2 m per step, straight along +x, measured by the engine.
    np.testing.assert_allclose(sim.pos[0], [-8.0, 0.0, 4.0], atol=1e-6)
    carry_on(sim, 8)
    np.testing.assert_allclose(sim.pos[0], [8.0, 0.0, 4.0], atol=1e-6)
    carry_on(sim, 1)
    assert sim.status[0] == HOVERING and sim.node[0] == sim.layout.n_ports + 1
    np.testing.assert_allclose(sim.pos[0], [10.0, 0.0, 4.0], atol=1e-6)


def carry_on(sim: VertiportSim, steps: int) -> None:
    for _ in range(steps):
        sim.step(sim.actions.continue_ if sim.status[sim.acting] in (TAXIING, ARRIVING)
                 else sim.actions.stay)


def crossing(sim: VertiportSim, second_turn_action: int) -> dict:
    """A: spot 0 (-10, 0) -> spot 1 (10, 0); B: spot 2 (0, -10) -> spot 3 (0, 10).
    Their paths cross at the origin; A's second turn decides."""
    hover_at(sim, 0, 0)
    hover_at(sim, 1, 2)
    sim.step(spot_action(sim, 1))  # A
    sim.step(spot_action(sim, 3))  # B
    # A at (-6, 0) flying +x at 8 m/s, B at (0, -8) flying +y: dp = (-6, 8), dv = (8, -8),
    # t_min = 112 / 128 = 0.875 s, D_min = |(1, 1)| = 1.41 m <= 3 m: a predicted conflict.
    np.testing.assert_allclose(sim.pos[0, :2], [-6.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(sim.pos[1, :2], [0.0, -8.0], atol=1e-6)
    _, info = sim.step(second_turn_action)
    carry_on(sim, 30)
    return info


def test_continue_through_a_conflict_loses_separation():
    sim = make_sim()
    info = crossing(sim, sim.actions.continue_)
    assert info["reward_terms"]["safety"] == -5.0
    # Every turn spent continuing into the predicted conflict is one more S = -5 event.
    assert sim.metrics.collisions >= 1
    assert sim.metrics.separation_losses >= 1
    assert (sim.status == HOVERING).all()  # both still reach their spots


def test_avoid_collision_keeps_separation_in_the_engine():
    sim = make_sim()
    info = crossing(sim, sim.actions.avoid)
    assert info["reward_terms"]["safety"] == 5.0
    assert sim.metrics.collisions == 0 and sim.metrics.avoided_conflicts == 1
    assert sim.metrics.separation_losses == 0 and sim.metrics.contacts == 0
    assert (sim.status == HOVERING).all()
    np.testing.assert_allclose(sim.pos[0], [10.0, 0.0, 4.0], atol=1e-6)


def test_head_on_meeting_is_a_contact_measured_by_the_engine():
    sim = make_sim()
    hover_at(sim, 0, 0)  # (-10, 0)
    hover_at(sim, 1, 1)  # (10, 0)
    sim.step(spot_action(sim, 4))  # A -> (14, 0)
    sim.step(spot_action(sim, 5))  # B -> (-14, 0): the same line, opposite directions
    carry_on(sim, 30)
    assert sim.metrics.contacts >= 1
    assert sim.metrics.separation_losses >= 1


def test_gust_reduces_the_step_displacement():
    sim = make_sim(**{"uncertainty.wind_gust_prob": 1.0,
                      "uncertainty.gust_speed_loss_range": [1.0, 1.0]})
    hover_at(sim, 0, 0)
    hover_at(sim, 1, 3)
    sim.step(spot_action(sim, 1))
    # A gust that takes the whole displacement away: the vehicle does not advance.
    np.testing.assert_allclose(sim.pos[0], [-10.0, 0.0, 4.0], atol=1e-6)
    sim2 = make_sim(**{"uncertainty.wind_gust_prob": 1.0,
                       "uncertainty.gust_speed_loss_range": [0.5, 0.5]})
    hover_at(sim2, 0, 0)
    hover_at(sim2, 1, 3)
    sim2.step(spot_action(sim2, 1))
    np.testing.assert_allclose(sim2.pos[0], [-9.0, 0.0, 4.0], atol=1e-6)


def test_parked_and_hovering_vehicles_cost_the_engine_nothing():
    sim = make_sim()
    hover_at(sim, 0, 0)
    hover_at(sim, 1, 3)
    assert not sim.physics.any_dynamic
    sim.step(spot_action(sim, 1))
    assert sim.physics._dynamic.tolist() == [True, False]


@pytest.mark.parametrize("rate_hz, expected", [(48.0, 12), (45.0, 12), (100.0, 25)])
def test_engine_substeps_meet_the_physics_rate(rate_hz, expected):
    sim = VertiportSim(load_config("paper", **{"flight.physics_rate_hz": rate_hz}))
    assert sim.physics.substeps == expected
    assert sim.physics.substeps / sim.dt_s >= rate_hz


def test_copies_get_their_own_physics_world():
    """supersuit clones envs with cloudpickle; copies must not share one pybullet client."""
    import copy
    import pickle

    from marl_vertiport.gym_env import VertiportEnv

    env = VertiportEnv()
    env.reset(seed=4)
    for _ in range(30):
        env.step(env.action_space.sample())
    twin = pickle.loads(pickle.dumps(env))
    other = copy.deepcopy(env)
    assert len({env.sim.physics.client, twin.sim.physics.client, other.sim.physics.client}) == 3
    np.testing.assert_array_equal(twin.sim.pos, env.sim.pos)
    # Stepping one copy leaves the others' bodies where they were.
    before = twin.sim.pos.copy()
    for _ in range(20):
        env.step(env.action_space.sample())
    np.testing.assert_array_equal(twin.sim.pos, before)
    # A copy continues exactly like the original under the same actions.
    a, b = pickle.loads(pickle.dumps(env)), env
    for _ in range(50):
        action = b.action_space.sample()
        oa, ra, *_ = a.step(action)
        ob, rb, *_ = b.step(action)
        assert ra == rb
        np.testing.assert_array_equal(oa["observation"]["evtol_nodes"], ob["observation"]["evtol_nodes"])
