"""Schedule windows, flight plans and the battery model, checked by hand.

Seed 0 of the paper config places (checked in ``new_sim``): evtol_0 on the charging port
(node 2), evtol_1 on normal port 1, evtol_2 on normal port 0, evtol_3 at hover spot 7;
take-offs scheduled at minutes 16, 15, 13 and evtol_3's landing at minute 15.
In flight a vehicle covers 8 m/s * 0.25 s = 2 m per step; cruise drains 0.5 %/m (1.0 % per
full step), a vehicle that moved < 1 m drains 2 %, idling on a normal port 4 %, and a working
charging port adds 10 %.
"""

import math

import numpy as np
import pytest

from helpers import seed0_sim

from marl_vertiport.config import load_config
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, DELAYED, EARLY, NO_OPERATION, ON_PORT, ON_TIME, OUT_OF_SERVICE,
    PENDING_LANDING, PENDING_TAKEOFF, TAXIING,
)

STAY, TAKEOFF, CONTINUE = 0, 1, 12
STEP_M = 2.0


def new_sim(**overrides) -> VertiportSim:
    return seed0_sim(**overrides)


def act(sim, v, action, minute=None):
    sim.acting = v
    if minute is not None:
        sim.minute = minute
    return sim.step(action)


def idle(sim):
    """One step in which the acting vehicle stays (or continues, when in transit)."""
    v = sim.acting
    return sim.step(STAY if sim.action_mask(v)[STAY] else CONTINUE)


def drain(metres: float) -> float:
    return 0.5 * metres if metres >= 1.0 else 2.0


# ------------------------------------------------------------------ schedule status
@pytest.mark.parametrize("kind, rel, expected", [
    (PENDING_TAKEOFF, -6, EARLY),     # more than 5 min before the take-off time
    (PENDING_TAKEOFF, -5, ON_TIME),
    (PENDING_TAKEOFF, 0, ON_TIME),
    (PENDING_TAKEOFF, 5, ON_TIME),
    (PENDING_TAKEOFF, 6, DELAYED),    # more than 5 min after
    (PENDING_LANDING, -12, ON_TIME),  # landing early is never "early"
    (PENDING_LANDING, 5, ON_TIME),
    (PENDING_LANDING, 6, DELAYED),
    (NO_OPERATION, 30, ON_TIME),
])
def test_schedule_status_boundaries(kind, rel, expected):
    sim = new_sim()
    sim.minute = 40
    sim.pending_kind[1] = kind
    sim.pending_time[1] = 40 - rel  # rel = minute - scheduled time
    status = sim.schedule_status()
    assert status[1] == expected
    # the others: evtol_0 (16), evtol_2 (13) pending take-offs and evtol_3's landing (15) are
    # all more than 5 minutes late at minute 40
    assert status[[0, 2, 3]].tolist() == [DELAYED] * 3


# ------------------------------------------------------------------ flight plans
def land_evtol_3(rng_seed: int):
    """evtol_2 takes off (frees port 0); evtol_3 then lands there from hover spot 7.
    Returns the sim, evtol_3's battery drain per step, and the draw expected for the next
    take-off offset: the first draw of the generator as it was before the touchdown step."""
    sim = new_sim()
    act(sim, 2, TAKEOFF, 0)
    sim.rng = np.random.default_rng(rng_seed)  # vary the draw of the next take-off time
    sim.battery[3] = 100.0
    drains, info = [], None
    act(sim, 3, 2 + 0)
    drains.append(100.0 - sim.battery[3])
    while sim.status[3] == TAXIING:
        before = sim.battery[3]
        clone = np.random.default_rng()
        clone.bit_generator.state = sim.rng.bit_generator.state
        _, info = act(sim, 3, CONTINUE)
        drains.append(before - sim.battery[3])
        assert len(drains) < 30
    assert info["touchdowns"] == 1
    return sim, drains, int(clone.integers(10, 20 + 1))


def test_landing_flight_battery_and_next_plan():
    sim, drains, _ = land_evtol_3(0)
    assert sim.status[3] == ON_PORT and sim.node[3] == 0 and sim.node_occupant[0] == 3
    # route: 2 m pieces along |spot 7 - port 0| at 4 m altitude, then down 4 - 0.15 = 3.85 m
    # (2 m + 1.85 m); the last piece of a leg is shorter than a step
    d = float(np.linalg.norm(sim.layout.node_xy_m[7] - sim.layout.node_xy_m[0]))
    n_full = math.floor(d / STEP_M)
    pieces = [STEP_M] * n_full + [d - STEP_M * n_full, 2.0, 1.85]
    assert len(drains) == len(pieces)
    assert drains == pytest.approx([drain(p) for p in pieces])  # e.g. 1, ..., 1, 0.925
    # landing cleared -> new plan: take off 10..20 minutes after the touchdown minute
    assert sim.pending_kind[3] == PENDING_TAKEOFF
    assert sim.metrics.completed_trips == 1 and sim.metrics.landings == 1


def test_takeoff_time_drawn_10_to_20_minutes_after_touchdown():
    offsets = set()
    for seed in range(40):
        sim, _, drawn = land_evtol_3(seed)
        touchdown = sim.minute  # the clock after the step in which it touched down
        offset = sim.pending_time[3] - touchdown
        assert offset == drawn  # uniform integer in [10, 20] from the env's generator
        assert 10 <= offset <= 20
        offsets.add(int(offset))
    assert min(offsets) == 10 and max(offsets) == 20  # both ends of the window are drawn


def test_landing_deadline_is_reentry_plus_15():
    sim = new_sim()
    act(sim, 1, TAKEOFF, 15)
    seen = [DEPARTING]
    for _ in range(200):
        prev_battery = sim.battery[1]
        idle(sim)
        s = int(sim.status[1])
        if s != seen[-1]:
            seen.append(s)
        if s == AWAY:
            moved = float(np.linalg.norm(sim.pos[1] - sim.prev_pos[1]))
            assert prev_battery - sim.battery[1] == pytest.approx(drain(moved))
        if s == ARRIVING:
            break
    assert seen == [DEPARTING, AWAY, ARRIVING]
    # re-entered during this step: the clock now reads the re-entry minute
    assert sim.pending_kind[1] == PENDING_LANDING
    assert sim.pending_time[1] == sim.minute + 15
    assert float(np.linalg.norm(sim.pos[1, :2])) < sim.layout.airspace_radius_m


# ------------------------------------------------------------------ battery per step
def test_battery_one_step_for_the_whole_fleet():
    sim = new_sim()
    sim.battery[:] = [50.0, 50.0, 50.0, 50.0]
    act(sim, 1, STAY)
    # charger +10, normal ports -4, hovering -2
    assert sim.battery.tolist() == [60.0, 46.0, 46.0, 48.0]


def test_battery_clipped_to_0_and_100():
    sim = new_sim()
    sim.battery[:] = [95.0, 3.0, 100.0, 100.0]
    act(sim, 0, STAY)
    # 95 + 10 = 105 -> 100; 3 - 4 = -1 -> 0 (on the ground: no depletion); 96; 98
    assert sim.battery.tolist() == [100.0, 0.0, 96.0, 98.0]
    assert sim.status[1] == ON_PORT and sim.metrics.battery_depletions == 0


def test_takeoff_climb_drains_per_metre():
    sim = new_sim()
    act(sim, 1, TAKEOFF, 15)
    # climbs 0.15 -> 2.15 m: 2 m * 0.5 = 1.0
    assert sim.pos[1, 2] == pytest.approx(2.15)
    assert sim.battery[1] == pytest.approx(99.0)


@pytest.mark.parametrize("metres, expected", [(1.5, 100 - 0.75), (0.5, 100 - 2.0)])
def test_short_moves_count_as_hovering(metres, expected):
    sim = new_sim()
    # evtol_3 taxis from its hover spot; its first waypoint is `metres` away, so it flies just
    # that far this step (a step ends at a waypoint). >= 1 m is cruise (0.5 %/m), less is the
    # 2 % hover drain. A second waypoint keeps the leg from ending (and snapping to a node).
    start = sim.pos[3].copy()
    sim.status[3] = TAXIING
    sim._set_route(3, [start + np.array([metres, 0.0, 0.0]), start + np.array([9.0, 0.0, 0.0])],
                   start[2])
    sim.physics.make_dynamic(3)
    act(sim, 3, CONTINUE)
    assert sim.pos[3, 0] - start[0] == pytest.approx(metres)
    assert sim.battery[3] == pytest.approx(expected)


def test_failed_charger_does_not_charge():
    sim = new_sim(**{"uncertainty.charger_failure_prob": 1.0})
    sim.battery[0] = 50.0
    _, info = act(sim, 0, STAY)
    assert info["charger_failures"] == 1
    assert sim.battery[0] == 46.0  # 50 - 4 idle instead of + 10


def test_battery_stays_within_bounds_in_a_random_run():
    sim = VertiportSim(load_config("paper_uncertain"))
    sim.reset(np.random.default_rng(5))
    rng = np.random.default_rng(1)
    for _ in range(300):
        sim.step(int(rng.choice(np.flatnonzero(sim.action_mask(sim.acting)))))
        assert np.all((sim.battery >= 0.0) & (sim.battery <= 100.0))


# ------------------------------------------------------------------ depletion
def test_depletion_while_hovering():
    sim = new_sim()
    sim.battery[3] = 1.5
    _, info = act(sim, 0, STAY)
    # 1.5 - 2 = -0.5 -> 0 in the air: one depletion, emergency landing, out of service
    assert sim.battery[3] == 0.0
    assert info["battery_depletions"] == 1 and sim.metrics.battery_depletions == 1
    assert sim.status[3] == OUT_OF_SERVICE and sim.pending_kind[3] == NO_OPERATION
    assert sim.node_occupant[7] == -1  # its hover spot is free again
    assert sim.pos[3, 2] == pytest.approx(0.15)  # on the ground
    for _ in range(5):
        idle(sim)
    assert sim.metrics.battery_depletions == 1 and sim.battery[3] == 0.0


def test_depletion_while_away():
    sim = new_sim()
    act(sim, 2, TAKEOFF, 13)
    for _ in range(100):
        if sim.status[2] == AWAY:
            break
        act(sim, 2, CONTINUE)
    assert sim.status[2] == AWAY
    sim.battery[2] = 0.9
    act(sim, 2, CONTINUE)  # 2 m of cruise: 0.9 - 1.0 = -0.1 -> clipped to 0
    assert sim.battery[2] == 0.0
    assert sim.metrics.battery_depletions == 1 and sim.status[2] == OUT_OF_SERVICE


# ------------------------------------------------------------------ completed delays
def test_completed_operations_add_their_lateness():
    sim = new_sim()
    act(sim, 1, TAKEOFF, 20)    # scheduled 15: 5 late, within the tolerance -> 0
    act(sim, 2, TAKEOFF, 21)    # scheduled 13: 8 late
    act(sim, 3, 2 + 0, 22)      # landing scheduled 15: 7 late
    assert sim.completed_delay.tolist() == [0.0, 0.0, 8.0, 7.0]
    assert sim.delay.tolist() == [7.0, 0.0, 0.0, 0.0]  # evtol_0: minute 23 - 16, still pending
    # mean delay of the episode: (7 + 0 + 8 + 7) / 4
    assert sim.episode_metrics()["mean_delay_min"] == pytest.approx(5.5)


def test_depletion_keeps_the_lateness_of_the_undone_operation():
    sim = new_sim()
    sim.battery[3] = 1.5  # evtol_3 hovers, landing scheduled at minute 15
    act(sim, 0, STAY, 30)
    # depleted during the step ending at minute 31: 31 - 15 = 16 minutes late, kept
    assert sim.status[3] == OUT_OF_SERVICE
    assert sim.completed_delay[3] == 16.0 and sim.delay[3] == 0.0


def test_minutes_per_step_drives_the_clock_and_windows():
    sim = VertiportSim(load_config("paper", **{"schedule.minutes_per_step": 2.0}))
    sim.reset(np.random.default_rng(0))
    for step in range(5):
        assert sim.minute == 2.0 * step
        idle(sim)
    assert sim.minute == 10.0 and sim.step_count == 5
    # A vehicle 8 scheduled minutes late after a few 2-minute steps is delayed by 8 minutes.
    sim.pending_kind[1], sim.pending_time[1] = PENDING_TAKEOFF, 2.0
    sim._update_delays()
    assert sim.delay[1] == 8.0 and sim.schedule_status()[1] == DELAYED
