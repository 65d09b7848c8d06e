"""The ATC's energy check (``atc.energy_check``) and the stranded-vehicle metric, on situations
worked out by hand from seed 0 of the paper config (placement in ``helpers.seed0_sim``).

A flight covers 2 m per step at 0.5 %/m (1 % a step); a vehicle on a port stands at z = 0.15 m.
The move of evtol_3 between neighbouring hover spots of the ring of 7 (radius 12 m), from node 7
to node 6, is 2 * 12 * sin(pi / 7) = 10.41 m at 4 m: 5 steps of 2 m (5 %) and one of 0.41 m,
shorter than 1 m, which costs a hover step (2 %): 7 %. With the 5 % reserve it is cleared
above 12 %. The taxi of evtol_1 to the charging port (node 2) at
(0, 8, 0.15): up 1.925 %, across 10 m 5 %, down 1.925 %: 8.85 %.
"""

import numpy as np
import pytest

from helpers import seed0_sim

from marl_vertiport.sim.schema import HOVERING, ON_PORT, OUT_OF_SERVICE
from marl_vertiport.sim.energy import leg_energy_pct

STAY, TAKEOFF, CONTINUE = 0, 1, 12
SPOT = 2 + 6  # action "move to node 6", the hover spot next to evtol_3


def test_leg_energy_by_hand():
    sim = seed0_sim()
    bat = sim.cfg.battery
    assert leg_energy_pct(10.0, 2.0, bat) == pytest.approx(5.0)  # 5 full steps of 2 m
    assert leg_energy_pct(9.0, 2.0, bat) == pytest.approx(4.5)  # 4 steps of 2 m, one of 1 m
    assert leg_energy_pct(8.5, 2.0, bat) == pytest.approx(6.0)  # last 0.5 m is a hover step
    assert leg_energy_pct(0.0, 2.0, bat) == 0.0


def test_taxi_energy_by_hand():
    sim = seed0_sim()
    assert sim.energy.hop_pct[7, 6] == pytest.approx(7.0)
    assert sim.energy.hop_pct[1, 2] == pytest.approx(8.85)
    assert sim.energy.hop_pct[1, 1] == 0.0
    assert sim.flight_energy_pct(3, SPOT) == pytest.approx(7.0)


@pytest.mark.parametrize("battery, cleared", [(12.0, False), (12.1, True), (60.0, True)])
def test_move_is_cleared_only_if_the_battery_can_finish_it(battery, cleared):
    sim = seed0_sim()
    sim.battery[3] = battery
    mask = sim.action_mask(3)
    assert bool(mask[SPOT]) == cleared
    assert mask[STAY] == 1 and mask.sum() >= 1
    unchecked = seed0_sim(**{"atc.energy_check": False})
    unchecked.battery[3] = battery
    assert unchecked.action_mask(3)[SPOT] == 1  # the paper's ATC clears it at any level


def test_takeoff_is_cleared_only_if_the_battery_can_finish_the_trip():
    sim = seed0_sim()
    trip = sim.energy.trip_pct[1, sim.dest[1]]
    # At least the distance flown (out to the destination, back to the charger, 8 m up and down)
    port, dest = sim.layout.node_xy_m[1], sim.layout.destination_xy_m[sim.dest[1]]
    charger = sim.layout.node_xy_m[2]
    assert trip >= 0.5 * (16.0 + np.linalg.norm(dest - port) + np.linalg.norm(charger - dest))
    reserve = sim.cfg.atc.energy_reserve_pct
    for battery, cleared in ((trip + reserve, False), (trip + reserve + 0.5, True)):
        sim.battery[1] = battery
        sim._mask_cache.clear()
        assert bool(sim.action_mask(1)[TAKEOFF]) == cleared
        assert sim.action_mask(1)[STAY] == 1


def test_the_move_costs_what_the_check_assumed():
    sim = seed0_sim()
    sim.battery[3] = 12.1
    sim.acting = 3
    sim.step(SPOT)
    for _ in range(20):
        if sim.status[3] == HOVERING:
            break
        v = sim.acting
        mask = sim.action_mask(v)
        sim.step(CONTINUE if v == 3 else STAY)
    assert sim.status[3] == HOVERING and sim.node[3] == 6
    assert sim.battery[3] == pytest.approx(12.1 - 7.0)
    assert not sim.lost[3]


@pytest.mark.parametrize("energy_check", [True, False])
def test_mask_is_never_empty(energy_check):
    sim = seed0_sim(**{"atc.energy_check": energy_check})
    rng = np.random.default_rng(3)
    for _ in range(300):
        v = sim.acting
        sim.battery[:] = np.where(sim.status == OUT_OF_SERVICE, sim.battery,
                                  rng.uniform(0.0, 100.0, sim.n))
        sim._mask_cache.clear()
        mask = sim.action_mask(v)
        assert mask.dtype == np.int8 and mask.sum() >= 1
        sim.step(int(rng.choice(np.flatnonzero(mask))))


def run_steps(sim, n):
    """Every vehicle stays (or continues) for ``n`` steps; returns the summed stranded infos."""
    marked = 0
    for _ in range(n):
        mask = sim.action_mask(sim.acting)
        _, info = sim.step(STAY if mask[STAY] else int(np.flatnonzero(mask)[0]))
        marked += info["stranded_ground"]
        assert info["vehicles_lost"] == info["stranded_ground"] + info["battery_depletions"]
    return marked


def test_empty_vehicle_on_a_normal_port_is_stranded_on_the_ground():
    sim = seed0_sim()
    sim.battery[2] = 0.0  # evtol_2 on normal port 0, the charging port held by evtol_0
    assert sim.status[2] == ON_PORT
    assert sim.stranded_threshold_pct(2) == pytest.approx(sim.energy.hop_pct[0, 2] + 5.0)
    assert sim.stranded_threshold_pct(0) == 0.0  # on the charging port: never stranded
    assert run_steps(sim, 1) == 1
    assert sim.lost.tolist() == [False, False, True, False]
    assert run_steps(sim, 9) == 0  # counted once
    m = sim.episode_metrics()
    assert (m["stranded_ground"], m["stranded_air"], m["stranded"]) == (1, 0, 1)
    assert m["service_min_lost"] == pytest.approx(9.0)  # lost at the end of minute 1, now 10
    assert m["battery_depletions"] == 0


def test_vehicle_that_can_still_reach_the_charger_is_not_stranded():
    sim = seed0_sim()
    sim.battery[2] = sim.energy.hop_pct[0, 2] + 5.0 + 4.0 + 1.0  # idling on a port drains 4 %
    assert run_steps(sim, 1) == 0 and not sim.lost[2]


def test_a_charger_blocked_for_the_day_strands_a_low_vehicle():
    sim = seed0_sim()
    sim.battery[2] = 30.0  # enough for the hop to the charger, not for a trip
    assert sim.stranded_threshold_pct(2) < 30.0
    sim.status[0] = OUT_OF_SERVICE  # evtol_0 sits on the only charging port for good
    sim.lost[0] = True
    assert sim.stranded_threshold_pct(2) == pytest.approx(sim.energy.trip_pct[0, sim.dest[2]] + 5.0)
    assert run_steps(sim, 1) == 1 and sim.lost[2]


def test_depletion_in_the_air_is_stranded_in_the_air():
    sim = seed0_sim(**{"atc.energy_check": False})
    assert sim.status[3] == HOVERING
    sim.battery[3] = 1.0  # hovering costs 2 % a step
    run_steps(sim, 1)
    m = sim.episode_metrics()
    assert sim.status[3] == OUT_OF_SERVICE and sim.lost[3]
    assert (m["stranded_air"], m["battery_depletions"], m["stranded"]) == (1, 1, 1)


@pytest.mark.parametrize("battery, must_land", [(19.6, True), (19.8, False), (60.0, False)])
def test_hovering_vehicle_must_land_while_it_still_can(battery, must_land):
    """evtol_3 hovers at spot 7 with normal port 0 free. Holding until its next turn (4 steps,
    2 % each) must leave the landing on port 0 (hop_pct[7, 0], about 6.67 %) and the 5 % reserve:
    below that only landings are cleared."""
    sim = seed0_sim()
    sim.node_occupant[0] = -1  # port 0 free (evtol_2 leaves it out of this check)
    sim.battery[3] = battery
    land = sim.energy.hop_pct[7, 0]
    assert land == pytest.approx(6.67, abs=0.01)  # 9.5 m across, 3.85 m down
    mask = sim.action_mask(3)
    assert mask[2] == 1  # the landing on port 0
    assert bool(mask[STAY]) == (not must_land)
    assert bool(mask[2 + 3:2 + 10].any()) == (not must_land)  # moves between hover spots
    assert mask.sum() >= 1


def test_hovering_vehicle_with_nowhere_to_land_may_hold():
    sim = seed0_sim()  # every port is taken
    sim.battery[3] = 10.0
    mask = sim.action_mask(3)
    assert mask[STAY] == 1 and not mask[2:5].any()
