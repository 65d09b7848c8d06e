"""Flight physics in pybullet: commanded speed, measured separation, engine contacts, and an
"avoid collision" that really keeps vehicles apart."""

import numpy as np
import pytest

from marl_vertiport.config import load_config, with_rules
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import ARRIVING, AWAY, HOVERING, OUT_OF_SERVICE, TAXIING

# Six hover spots on the axes, 10-14 m from the centre (at least 4 m apart); two vehicles.
SPOTS = [[-10.0, 0.0], [10.0, 0.0], [0.0, -10.0], [0.0, 10.0], [14.0, 0.0], [-14.0, 0.0]]


def make_sim(**overrides) -> VertiportSim:
    """Two vehicles on a layout of hover spots on the axes, under the rules v0 (the tests set
    up conflicts and contacts by hand, which the separation check of v1 rules out)."""
    cfg = with_rules(load_config("paper", fleet_size=2, **{"layout.hover_spots_xy_m": SPOTS},
                                 **overrides), 0)
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


def test_a_reversing_gust_never_pushes_a_climbing_vehicle_below_its_pad():
    """Every vehicle hit by a full reversal (u = 2) on every step: one taking off is pushed back
    down to its pad at most (a regression: it used to end about 1.85 m under the ground)."""
    from marl_vertiport.sim.schema import ON_CHARGER, ON_PORT

    cfg = load_config("paper", **{"uncertainty.wind_gust_prob": 1.0,
                                  "uncertainty.gust_speed_loss_range": [2.0, 2.0],
                                  "atc.energy_check": False})
    sim = VertiportSim(cfg)
    sim.reset(np.random.default_rng(0))
    took_off = 0
    for _ in range(40):
        v = sim.acting
        on_ground = sim.status[v] in (ON_PORT, ON_CHARGER)
        action = sim.actions.takeoff if on_ground and sim.action_mask(v)[sim.actions.takeoff] else (
            sim.actions.continue_ if sim.action_mask(v)[sim.actions.continue_] else sim.actions.stay)
        took_off += action == sim.actions.takeoff
        sim.step(action)
        inside = sim.status != AWAY
        assert (sim.pos[inside, 2] >= sim.park_z_m - 1e-9).all(), sim.pos[inside, 2]
    assert took_off >= 2


def test_an_emergency_landing_comes_down_beside_a_vehicle_on_the_ground_not_on_it():
    cfg = load_config("paper", **{"atc.energy_check": False})
    sim = VertiportSim(cfg)
    sim.reset(np.random.default_rng(0))
    v = sim.acting
    u = (v + 1) % sim.n
    xy = sim.layout.node_xy_m[sim.layout.n_ports]  # above the first hover spot
    for w in (u, v):  # both over the same point, at the hover altitude
        sim._release(w)
        sim.status[w] = HOVERING
        sim.has_target[w] = False
        sim.routes[w] = []
        sim.pos[w] = (xy[0], xy[1], cfg.flight.hover_altitude_m)
        sim.physics.make_static(w, sim.pos[w])
    sim._take_out_of_service(u)  # u comes down straight below
    np.testing.assert_allclose(sim.pos[u], (xy[0], xy[1], sim.park_z_m))
    sim.battery[v] = 1.0
    sim._mask_cache, sim._evtol_cache = {}, None
    sim.step(sim.actions.stay)  # one more minute of hovering empties v's battery
    assert sim.status[v] == OUT_OF_SERVICE and sim.pos[v, 2] == sim.park_z_m
    assert np.linalg.norm(sim.pos[v, :2] - sim.pos[u, :2]) >= sim._touch_m  # beside, not inside
    assert np.hypot(*sim.pos[v, :2]) < cfg.layout.airspace_radius_m


@pytest.mark.parametrize("movers,n_away", [(1, 1), (2, 10), (2, 1), (9, 3)])
def test_separation_of_a_fleet_is_measured_over_every_pair_with_a_mover(movers, n_away):
    """Sixteen vehicles (the pairs are measured on lists for a few, on arrays for many): the new
    losses of separation and the least distance are those of every present pair with a mover,
    each measured on its own over the step."""
    from marl_vertiport.sim.geometry import swept_min_distance_pair

    sim = VertiportSim(with_rules(load_config("large_overloaded"), 0))
    sim.reset(np.random.default_rng(0))
    sep = sim.cfg.safety.min_separation_m
    for seed in range(20):
        rng = np.random.default_rng(seed)
        n = sim.n
        start = rng.uniform(-12.0, 12.0, (n, 3))
        moving = sorted(rng.choice(n, movers, replace=False).tolist())
        end = start.copy()
        end[moving] += rng.uniform(-3.0, 3.0, (movers, 3))
        status = [HOVERING] * n
        away = set(rng.choice(n, n_away, replace=False).tolist())
        for v in away:
            status[v] = AWAY
        sim.prev_pos[:] = start
        sim.pos[:] = end
        sim._moved, sim._deflected, sim._gone = moving, [], set()
        sim.sep_state, sim.contact_state = set(), set()
        sim.metrics.separation_losses, sim.metrics.min_separation_m = 0, float("inf")
        lost, _ = sim._measure_separation(status, start.tolist(), end.tolist())
        live = [v for v in moving if v not in away]
        dist = {(a, b): swept_min_distance_pair(tuple(start[a]), tuple(end[a]),
                                                tuple(start[b]), tuple(end[b]))
                for a in range(n) for b in range(a + 1, n)
                if a not in away and b not in away and (a in live or b in live)}
        if not dist:
            assert lost == 0
            continue
        assert lost == sum(d < sep for d in dist.values())
        assert sim.sep_state == {pair for pair, d in dist.items() if d < sep}
        assert sim.metrics.min_separation_m == pytest.approx(min(dist.values()), rel=1e-12)
