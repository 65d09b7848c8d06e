"""The paper's reward (eq. 2) term by term, on situations worked out by hand.

Seed 0 of the paper config places (checked in ``new_sim``):
  evtol_0 on the charging port (node 2), take-off scheduled at minute 16;
  evtol_1 on normal port 1 at (6, 0),     take-off scheduled at minute 15;
  evtol_2 on normal port 0 at (-6, 0),    take-off scheduled at minute 13;
  evtol_3 hovering at hover spot node 7,  landing scheduled at minute 15.
Actions: 0 stay, 1 take off, 2 + node (move / land), 12 continue, 13 avoid collision.
A vehicle in flight covers 8 m/s * 0.25 s = 2 m per step and drains 0.5 %/m -> 1.0 %.
R = 0.3 tau + 0.3 gamma + 0.35 lambda + 0.1 beta + 0.35 S.
"""

import math

import numpy as np
import pytest

from helpers import seed0_sim

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import HOVERING, NO_OPERATION, ON_PORT, PENDING_LANDING, TAXIING

W = (0.3, 0.3, 0.35, 0.1, 0.35)
TAKEOFF, CONTINUE, AVOID, STAY = 1, 12, 13, 0


def new_sim(**overrides) -> VertiportSim:
    return seed0_sim(**overrides)


def weighted(terms) -> float:
    return (W[0] * terms["takeoff"] + W[1] * terms["landing"] + W[2] * terms["battery"]
            + W[3] * terms["delay"] + W[4] * terms["safety"])


def act(sim, v, action, minute=None):
    sim.acting = v
    if minute is not None:
        sim.minute = minute
    reward, info = sim.step(action)
    assert reward == pytest.approx(weighted(info["reward_terms"]))
    return reward, info["reward_terms"], info


# ------------------------------------------------------------------ take-off term tau
@pytest.mark.parametrize("minute, tau", [(9, -5.0), (10, 5.0), (15, 5.0), (20, 5.0), (21, -5.0)])
def test_takeoff_term_window(minute, tau):
    sim = new_sim()
    r, t, info = act(sim, 1, TAKEOFF, minute)  # scheduled at 15: on time for 10..20
    assert t["takeoff"] == tau and info["takeoff"] and info["good_takeoff"] == (tau > 0)
    assert t["landing"] == 0.0 and t["safety"] == 0.0
    # climbs 2 m -> battery 100 - 1 = 99 -> lambda = 5 * 0.99 = 4.95; the plan is done -> beta = +5
    assert t["battery"] == pytest.approx(4.95) and t["delay"] == pytest.approx(5.0)
    assert r == pytest.approx(0.3 * tau + 0.35 * 4.95 + 0.1 * 5)  # 3.7325 or 0.7325


@pytest.mark.parametrize("battery, tau, lam", [(30.0, -5.0, -5.0), (30.5, 5.0, -5.0), (40.0, 5.0, 1.95)])
def test_takeoff_needs_battery_above_30(battery, tau, lam):
    sim = new_sim(**{"atc.energy_check": False})  # the paper's ATC clears any take-off
    sim.battery[1] = battery
    r, t, _ = act(sim, 1, TAKEOFF, 15)
    # tau looks at the battery before the step (> 30 needed); lambda at the battery after
    # the 1 % climb: 29 and 29.5 are < 30 -> -5; 39 -> 5 * 0.39 = 1.95
    assert (t["takeoff"], t["battery"]) == (tau, pytest.approx(lam))
    assert r == pytest.approx(0.3 * tau + 0.35 * lam + 0.1 * 5)


def test_no_takeoff_term_without_takeoff():
    sim = new_sim()
    r, t, _ = act(sim, 1, STAY, 0)
    # idle on a normal port: 100 - 4 = 96 -> lambda 4.8; R = 0.35 * 4.8 + 0.1 * 5 = 2.18
    assert t == {"takeoff": 0.0, "landing": 0.0, "battery": pytest.approx(4.8), "delay": 5.0,
                 "safety": 0.0}
    assert r == pytest.approx(2.18)


def test_failed_takeoff_gives_no_takeoff_term():
    sim = new_sim(**{"uncertainty.takeoff_failure_prob": 1.0})
    r, t, info = act(sim, 1, TAKEOFF, 15)
    assert info["takeoff_failed"] and not info["takeoff"]
    assert sim.status[1] == ON_PORT and sim.node[1] == 1
    assert sim.metrics.failed_takeoffs == 1 and sim.metrics.takeoffs == 0
    # stays on the ground: 100 - 4 = 96 -> R = 0.35 * 4.8 + 0.5 = 2.18, tau = 0
    assert t["takeoff"] == 0.0 and r == pytest.approx(2.18)


# ------------------------------------------------------------------ landing term gamma
def sim_with_free_port() -> VertiportSim:
    """evtol_2 takes off from port 0 (minute 0 -> 1), which frees port 0 for evtol_3."""
    sim = new_sim()
    act(sim, 2, TAKEOFF)
    assert sim.node_occupant[0] == -1
    sim.battery[3] = 100.0
    return sim


@pytest.mark.parametrize("minute, gamma", [(0, 5.0), (15, 5.0), (20, 5.0), (21, -5.0)])
def test_landing_term_window(minute, gamma):
    sim = sim_with_free_port()
    r, t, info = act(sim, 3, 2 + 0, minute)  # land on port 0; scheduled at 15, deadline 15 + 5
    assert info["landing"] and t["landing"] == gamma and t["takeoff"] == 0.0
    assert sim.status[3] == TAXIING and sim.node_occupant[0] == 3
    # flies 2 m -> 99 -> lambda 4.95; landing cleared, no pending operation -> beta +5
    assert r == pytest.approx(0.3 * gamma + 0.35 * 4.95 + 0.5)  # 3.7325 or 0.7325


def test_landing_needs_battery_above_30():
    sim = sim_with_free_port()
    sim.battery[3] = 30.0
    r, t, _ = act(sim, 3, 2 + 0, 15)
    # gamma: 30 is not > 30 -> -5; lambda: 30 - 1 = 29 < 30 -> -5
    assert (t["landing"], t["battery"]) == (-5.0, -5.0)
    assert r == pytest.approx(-1.5 - 1.75 + 0.5)  # -2.75


def test_move_between_hover_spots_is_not_a_landing():
    sim = new_sim()
    r, t, info = act(sim, 3, 2 + 3, 0)  # hover spot 7 -> hover spot 3
    assert not info["landing"] and t["landing"] == 0.0
    assert sim.pending_kind[3] == PENDING_LANDING
    assert r == pytest.approx(0.35 * 4.95 + 0.5)  # 2.2325


# ------------------------------------------------------------------ battery term lambda
@pytest.mark.parametrize("v, before, lam", [
    (1, 34.0, 1.5),    # normal port: 34 - 4 = 30 >= 30 -> 5 * 0.30
    (1, 33.9, -5.0),   # 29.9 < 30 -> penalty
    (1, 3.0, -5.0),    # clipped at 0, still the penalty
    (0, 95.0, 5.0),    # charging port: 95 + 10 = 105 -> clipped to 100 -> 5 * 1.0
    (0, 25.0, 1.75),   # 25 + 10 = 35 -> 5 * 0.35: the battery after the step counts
])
def test_battery_term_uses_battery_after_the_step(v, before, lam):
    sim = new_sim()
    sim.battery[v] = before
    r, t, _ = act(sim, v, STAY, 0)
    assert t["battery"] == pytest.approx(lam)
    assert r == pytest.approx(0.35 * lam + 0.5)


# ------------------------------------------------------------------ delay term beta
@pytest.mark.parametrize("minute, delay", [(0, 0.0), (19, 0.0), (20, 6.0), (24, 10.0)])
def test_delay_term(minute, delay):
    sim = new_sim()
    r, t, _ = act(sim, 1, STAY, minute)
    # scheduled at 15; after the step the clock reads minute + 1: late by minute + 1 - 15,
    # a delay only beyond 5 minutes (20 -> 21 -> 6 late)
    assert sim.delay[1] == delay
    beta = -5.0 + 10.0 * math.exp(-delay)  # +5 when on time, -4.9752 for 6 minutes
    assert t["delay"] == pytest.approx(beta)
    assert r == pytest.approx(0.35 * 4.8 + 0.1 * beta)


# ------------------------------------------------------------------ safety term S
def put_on_route(sim, v, start, end):
    """Vehicle ``v`` taxiing in a straight line from ``start`` to ``end`` (x, y, z)."""
    sim._release(v)
    sim.pos[v] = sim.prev_pos[v] = start
    sim.status[v] = TAXIING
    sim.pending_kind[v] = NO_OPERATION
    sim._set_route(v, [np.array(end, dtype=float)], end[2])
    sim.physics.make_dynamic(v, sim.pos[v])
    sim._refresh_conflicts()  # the probe runs at the end of each step; rerun it after the edit


def crossing(sim, alt_b=4.0):
    # A: (-10, 0) -> (10, 0), B: (0, -10) -> (0, 10), both 8 m/s. dp = (-10, 10),
    # dv = (8, -8): t_min = -(dp.dv)/|dv|^2 = 160/128 = 1.25 s, D_min = |dp + 1.25 dv| = 0.
    put_on_route(sim, 0, (-10.0, 0.0, 4.0), (10.0, 0.0, 4.0))
    put_on_route(sim, 1, (0.0, -10.0, alt_b), (0.0, 10.0, alt_b))


@pytest.mark.parametrize("action, safety", [(CONTINUE, -5.0), (AVOID, 5.0)])
def test_safety_term_on_crossing_paths(action, safety):
    sim = new_sim()
    crossing(sim)
    r, t, info = act(sim, 0, action, 0)
    assert t["safety"] == safety and info["conflict"]
    assert sim.metrics.collisions == int(safety < 0)
    assert sim.metrics.avoided_conflicts == int(safety > 0)
    # A flies 2 m either way (ahead, or straight up to layer 12 m) -> 99 -> lambda 4.95
    assert r == pytest.approx(0.35 * 4.95 + 0.5 + 0.35 * safety)  # 0.4825 / 3.9825


def test_no_conflict_in_different_altitude_layers():
    sim = new_sim()
    crossing(sim, alt_b=12.0)  # same ground paths, but 12 - 4 = 8 m >= 3 m apart vertically
    r, t, info = act(sim, 0, CONTINUE, 0)
    assert t["safety"] == 0.0 and not info["conflict"]
    assert r == pytest.approx(0.35 * 4.95 + 0.5)  # 2.2325


def test_no_conflict_when_closest_approach_is_past():
    sim = new_sim()
    # A: (2, 0) -> (12, 0), B: (0, 2) -> (0, 12): the paths come 2.83 m close (< 3 m), but
    # dp = (2, -2), dv = (8, -8): t_min = -(16 + 16)/128 = -0.25 s < 0, moving apart.
    put_on_route(sim, 0, (2.0, 0.0, 4.0), (12.0, 0.0, 4.0))
    put_on_route(sim, 1, (0.0, 2.0, 4.0), (0.0, 12.0, 4.0))
    _, t, _ = act(sim, 0, CONTINUE, 0)
    assert t["safety"] == 0.0


def test_no_safety_term_for_a_vehicle_not_in_transit():
    sim = new_sim()
    crossing(sim)  # evtol_0 and evtol_1 conflict, but evtol_2 (on its port) acts
    _, t, info = act(sim, 2, STAY, 0)
    assert t["safety"] == 0.0 and not info["conflict"]


def test_safety_term_from_move_actions():
    """Two hovering vehicles sent across the vertiport on mirror-image paths."""
    def setup():
        sim = new_sim()
        # evtol_2 moved by hand from its port to hover spot 5 (mirror image of spot 7)
        sim._release(2)
        sim._occupy(2, 5)
        sim.pos[2] = sim.prev_pos[2] = [*sim.layout.node_xy_m[5], sim.layout.node_z_m[5]]
        sim.physics.make_static(2, sim.pos[2])
        sim.status[2] = HOVERING
        # hovering vehicles are not in transit when they act: S = 0 for the move itself
        assert act(sim, 3, 2 + 3)[1]["safety"] == 0.0   # spot 7 -> spot 3
        assert act(sim, 2, 2 + 9)[1]["safety"] == 0.0   # spot 5 -> spot 9, one step later
        return sim

    # Spots 7 and 5 sit at angles 9pi/7 and 5pi/7, spots 3 and 9 at pi/7 and 13pi/7: the
    # chords 7->3 and 5->9 are mirror images across the x axis, at 3pi/14 = 38.6 deg to it,
    # and cross on it. evtol_3 left one step (2 m) earlier, so dp = (2 cos 38.6, -y),
    # dv = (0, 16 sin 38.6): D_min = 2 m * cos(38.6 deg) = 1.56 m <= 3 m, ahead (t_min > 0).
    sim = setup()
    _, t, _ = act(sim, 3, CONTINUE)
    assert t["safety"] == -5.0
    sim = setup()
    _, t, _ = act(sim, 3, AVOID)
    assert t["safety"] == 5.0
    assert sim.avoid_layer[3] == 0 and sim.leg_alt[3] == 12.0
    # evtol_3 now flies in the 12 m layer: evtol_2 at 4 m has no conflict with it any more
    _, t, _ = act(sim, 2, CONTINUE)
    assert t["safety"] == 0.0
