"""The separation check of rules v1 (marl_vertiport/sim/clearance.py): hand-built situations,
the protected volumes' geometry, and random play on every shipped scenario at 10 % uncertainty
with no loss of separation and no contact."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from marl_vertiport.config import load_config, with_rules
from marl_vertiport.sim.volumes import (
    TaxiMoves, box, boxes_apart, plan_distance, segments_clear, volume, volumes_clear,
)
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.invariants import violations
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_PORT, OUT_OF_SERVICE, TAXIING,
)

SHIPPED = ["paper", "paper_uncertain", "paper_uncertain_10", "small", "twin", "wide", "mid",
           "large", "large_overloaded", "fleet40", "fleet40_overloaded", "paper_overloaded"]
TEN = {"uncertainty.wind_gust_prob": 0.1, "uncertainty.charger_failure_prob": 0.1,
       "uncertainty.takeoff_failure_prob": 0.1, "uncertainty.action_misread_prob": 0.1,
       "uncertainty.position_noise_std_m": 1.0}
# Hover spots on the x axis beyond both ports, and one beside normal port 0 (3 m north of it).
SPOTS = [[-14.0, 0.0], [14.0, 0.0], [-6.0, 3.0], [0.0, -12.0]]
STAY, TAKEOFF = 0, 1


def make(fleet=2, rules=1, **overrides) -> VertiportSim:
    """The paper's pads with SPOTS as hover spots, ``fleet`` vehicles, every vehicle placed by
    hand after the reset (the seeded placement is moved away)."""
    cfg = load_config("paper", fleet_size=fleet, **{"layout.hover_spots_xy_m": SPOTS}, **overrides)
    sim = VertiportSim(with_rules(cfg, rules))
    sim.reset(np.random.default_rng(0))
    for v in range(sim.n):
        sim._release(v)
    return sim


def park(sim: VertiportSim, v: int, node: int) -> None:
    """Put vehicle ``v`` at rest on ``node`` (a pad: on the port; a hover spot: hovering)."""
    sim._release(v)
    sim._occupy(v, node)
    sim.pos[v] = sim._node_pos[node]
    sim.has_target[v] = False
    sim.status[v] = ON_PORT if sim._is_port[node] else HOVERING
    sim.physics.make_static(v, sim.pos[v])
    sim._reserve(v)
    sim._mask_cache = {}


def node_action(sim, node):
    return sim.actions.node_action(node)


# ------------------------------------------------------------------ geometry
def test_volume_extends_each_leg_behind_its_start_by_the_margin():
    vol = volume((0.0, 0.0, 0.15), [(0.0, 0.0, 8.0), (10.0, 0.0, 8.0)], 2.0, 0.15)
    climb, level = vol
    assert climb[4:] == (0.15, 8.0)  # the margin below the pad is cut at the ground
    assert level[:4] == (-2.0, 0.0, 10.0, 0.0) and level[4:] == (8.0, 8.0)
    descent = volume((5.0, 5.0, 12.0), [(5.0, 5.0, 4.0)], 2.0, 0.15)[0]
    assert descent[4:] == (4.0, 14.0)  # a reversing gust pushes a descent up


def test_layers_four_metres_apart_and_a_move_above_a_parked_vehicle_are_clear():
    h, v = 4.0, 3.5
    at4 = volume((0.0, 0.0, 4.0), [(10.0, 0.0, 4.0)], 2.0, 0.15)
    at8 = volume((0.0, 0.0, 8.0), [(10.0, 0.0, 8.0)], 2.0, 0.15)
    parked = volume((5.0, 0.0, 0.15), (), 0.0, 0.15)
    assert volumes_clear(at4, at8, h, v)
    assert volumes_clear(at4, parked, h, v)  # 3.85 m above it
    climb = volume((5.0, 3.9, 0.15), [(5.0, 3.9, 8.0)], 2.0, 0.15)
    assert not volumes_clear(climb, at4, h, v)  # 3.9 m beside a climb through 4 m
    assert volumes_clear(volume((5.0, 4.1, 0.15), [(5.0, 4.1, 8.0)], 2.0, 0.15), at4, h, v)
    assert plan_distance((0, 0, 10, 0, 0, 0), (5, -5, 5, 5, 0, 0)) == 0.0  # crossing


_coord = st.integers(-80, 80).map(lambda k: k / 4.0)  # metres, on a quarter-metre grid
_point = st.tuples(_coord, _coord, st.integers(1, 48).map(lambda k: k / 4.0))
_route = st.lists(_point, min_size=0, max_size=3)


@settings(max_examples=300, deadline=None)
@given(a=_point, b=_route, c=_point, d=_route)
def test_segments_clear_is_the_separation_thresholds_per_axis(a, b, c, d):
    """The quick plan-view box test inside segments_clear never changes its answer: two segments
    are clear when their altitude ranges or their plan-view projections are far enough apart."""
    h, v = 4.0, 3.5
    for s in volume(a, b, 2.0, 0.15):
        for t in volume(c, d, 2.0, 0.15):
            apart = s[4] - t[5] >= v or t[4] - s[5] >= v or plan_distance(s, t) >= h
            assert segments_clear(s, t, h, v) == apart


@settings(max_examples=150, deadline=None)
@given(start=_point, targets=st.lists(_route, min_size=1, max_size=6), c=_point, d=_route)
def test_moves_tested_at_once_clear_a_reservation_exactly_where_each_does(start, targets, c, d):
    """TaxiMoves.clear_of, which tests each distinct segment once, says what the box test and
    volumes_clear say of each move on its own; the node itself (no move) is never cleared."""
    h, v = 4.0, 3.5
    vols = [volume(start, route, 2.0, 0.15) if route else () for route in targets]
    other = volume(c, d, 2.0, 0.15)
    ok = TaxiMoves(vols).clear_of(other, box(other), h, v)
    for k, vol in enumerate(vols):
        expect = bool(vol) and (boxes_apart(box(vol), box(other), h, v)
                                or volumes_clear(vol, other, h, v))
        assert ok[k] == expect
    # Filling some nodes alone (the masks test only the moves they still allow) gives the same
    # answers there and leaves every other entry as it was.
    some = list(range(0, len(vols), 2))
    part = np.full(len(vols), -1, dtype=np.int8)
    TaxiMoves(vols).fill(part, some, other, box(other), h, v)
    assert [int(part[k]) for k in some] == [int(ok[k]) for k in some]
    assert all(part[k] == -1 for k in range(len(vols)) if k not in some)


# ------------------------------------------------------------------ hand-built situations
def test_take_off_under_an_inbound_vehicle_is_masked_until_it_is_down():
    sim = make()
    park(sim, 0, 0)  # evtol_0 on normal port 0 at (-6, 0)
    park(sim, 1, 3)  # evtol_1 hovering at spot 0 (-14, 0)
    sim.status[1] = ARRIVING  # inbound: cleared down to the spot beside port 0
    sim._release(1)
    sim.pos[1] = [-6.0, 3.0, 8.0]
    sim.physics.make_static(1, sim.pos[1])  # the engine's body there too
    sim.physics.make_dynamic(1)
    sim._occupy(1, 5)
    sim._set_route(1, [sim._node_pos[5].copy()], 8.0)
    sim._mask_cache = {}
    assert sim.action_mask(0)[TAKEOFF] == 0
    assert sim.mask_reasons(0)[TAKEOFF] == "separation: evtol_1"
    for _ in range(4):  # evtol_0 stays while evtol_1 descends 4 m at 2 m a step
        sim.acting = 0
        sim.step(STAY)
    assert sim.status[1] == HOVERING
    # Hovering 3 m beside the pad, 3.85 m up: a climb from the pad would pass it.
    assert sim.action_mask(0)[TAKEOFF] == 0
    park(sim, 1, 4)  # once it has moved on to spot 1, the pad is clear again
    assert sim.action_mask(0)[TAKEOFF] == 1


def test_a_move_across_a_pad_in_use_follows_the_departure_and_holds_until_its_way_clears():
    sim = make()
    park(sim, 0, 0)  # evtol_0 on normal port 0
    park(sim, 1, 3)  # evtol_1 hovering at (-14, 0): its way to normal port 1 crosses port 0
    sim.acting = 0
    sim.step(TAKEOFF)  # evtol_0 climbs from port 0
    assert sim.status[0] == DEPARTING
    to_port1 = node_action(sim, 1)
    assert sim.action_mask(1)[to_port1] == 1  # cleared behind the departure,
    sim.acting = 1
    sim.step(to_port1)
    assert sim.leaders[1] == (0,)  # following it
    acts, held, flown = sim.actions, 0, 0
    for _ in range(40):
        before = sim.pos[1].copy()
        a = acts.continue_ if sim.action_mask(sim.acting)[acts.continue_] else STAY
        sim.step(a)
        assert violations(sim) == []  # never within the separation
        if sim.status[1] == TAXIING:
            moved = np.abs(sim.pos[1] - before).max() > 1e-9
            held += not moved
            flown += moved
    assert held >= 1 and flown >= 5  # it held while the climb was in its way, then went on
    assert sim.status[1] == ON_PORT and sim.node[1] == 1 and sim.leaders[1] == ()
    # The metric counts exactly those steps (the departure ahead never held).
    assert sim.metrics.trail_hold_min == held * sim.minutes_per_step
    assert sim.episode_metrics()["trail_hold_min"] == held * sim.minutes_per_step
    # Without trailing, the move stays masked while the departure climbs.
    sim = make(**{"atc.trail_departures": False})
    park(sim, 0, 0)
    park(sim, 1, 3)
    sim.acting = 0
    sim.step(TAKEOFF)
    assert sim.action_mask(1)[to_port1] == 0
    assert sim.mask_reasons(1)[to_port1] == "separation: evtol_0"
    assert sim.action_mask(1)[node_action(sim, 6)] == 1  # to (0, -12): clear of it


def test_a_vehicle_yields_only_to_older_clearances():
    sim = make(fleet=3)
    park(sim, 0, 0)  # evtol_0 on normal port 0
    park(sim, 1, 1)  # evtol_1 on normal port 1
    park(sim, 2, 3)  # evtol_2 hovering at (-14, 0)
    sim.acting = 0
    sim.step(TAKEOFF)
    sim.acting = 1
    sim.step(TAKEOFF)
    sim.acting = 2
    sim.step(node_action(sim, 0))  # to port 0, behind evtol_0's climb
    assert sim.clear_seq[0] < sim.clear_seq[1] < sim.clear_seq[2]
    assert 1 not in sim.leaders[0] and 2 not in sim.leaders[0] and 2 not in sim.leaders[1]
    assert 0 in sim.leaders[2]


def test_without_chains_nothing_is_cleared_behind_a_departure_that_waits_itself():
    """``atc.trail_chains``: evtol_1's departure (west, over port 0) follows evtol_0's climb
    from port 0. With chains a move of evtol_2 to port 1 may follow evtol_1; without, it is
    masked until evtol_1 waits for no one, and then it may follow it."""
    for chains in (True, False):
        sim = make(fleet=3, **{"atc.trail_chains": chains})
        to_port1 = node_action(sim, 1)
        park(sim, 0, 0)  # evtol_0 on normal port 0, for the north
        park(sim, 1, 1)  # evtol_1 on normal port 1, for the west: across port 0
        park(sim, 2, 3)  # evtol_2 hovering at (-14, 0)
        sim.dest[0], sim.dest[1] = 0, 1
        sim._mask_cache = {}
        sim.acting = 0
        sim.step(TAKEOFF)
        sim.acting = 1
        sim.step(TAKEOFF)
        assert sim.leaders[1] == (0,)
        if chains:
            assert sim.action_mask(2)[to_port1] == 1
            continue
        assert sim.action_mask(2)[to_port1] == 0
        assert sim.mask_reasons(2)[to_port1] == "separation: evtol_1"
        while sim.leaders[1]:
            acts = sim.actions
            a = acts.continue_ if sim.action_mask(sim.acting)[acts.continue_] else STAY
            sim.step(a)
            assert violations(sim) == []
        assert sim.status[1] == DEPARTING and sim.action_mask(2)[to_port1] == 1


def test_overlapping_clearances_mask_the_second_and_disjoint_ones_are_both_legal():
    sim = make(fleet=3)
    park(sim, 0, 3)  # at (-14, 0)
    park(sim, 1, 4)  # at (14, 0)
    park(sim, 2, 6)  # at (0, -12)
    # evtol_0 cleared to normal port 1 (6, 0): its way at 4 m passes (0, 0) ... (6, 0);
    sim.acting = 0
    sim.step(node_action(sim, 1))
    # evtol_1 to normal port 0 would meet it head-on at the same altitude: masked,
    assert sim.action_mask(1)[node_action(sim, 0)] == 0
    # evtol_2 to the charging port (0, 8) crosses its way: masked too,
    assert sim.action_mask(2)[node_action(sim, 2)] == 0
    sim2 = make(fleet=2)
    park(sim2, 0, 3)
    park(sim2, 1, 4)
    sim2.acting = 0
    sim2.step(node_action(sim2, 0))  # (-14, 0) to port 0 (-6, 0): the west side only
    assert sim2.action_mask(1)[node_action(sim2, 1)] == 1  # (14, 0) to port 1: the east side


def test_two_vehicles_back_from_one_destination_hold_in_slots_of_their_own():
    sim = make(fleet=3)
    park(sim, 0, 3)
    park(sim, 1, 4)
    park(sim, 2, 6)
    dest = sim.layout.destination_xy_m[0]
    for v in (0, 1):
        sim._release(v)
        sim.status[v] = AWAY
        sim.returning[v] = False
        sim.physics.make_absent(v)
        sim.pos[v] = [dest[0], dest[1], sim.arrival_alt_m]
        sim.has_target[v] = False
        sim._finish_leg(v)  # at the destination: to a holding slot
    assert sim.slot_of[0] >= 0 and sim.slot_of[1] >= 0 and sim.slot_of[0] != sim.slot_of[1]
    gap = np.linalg.norm(sim.slot_pos[sim.slot_of[0]] - sim.slot_pos[sim.slot_of[1]])
    assert gap >= 2 * sim.clear_h_m
    assert sim.target[0][2] == sim.target[1][2] == sim.arrival_alt_m == 4.0  # the hover layer


def test_a_reentry_whose_inbound_path_is_reserved_holds_in_its_slot():
    sim = make(fleet=3)
    park(sim, 1, 4)  # evtol_1 hovering at (14, 0)
    slot = int(np.argmin(np.hypot(sim.slot_pos[:, 0], sim.slot_pos[:, 1] + 20.0)))  # south
    sim.status[0] = ARRIVING  # evtol_0 back in that slot
    sim.slot_of[0] = slot
    sim.pos[0] = sim.slot_pos[slot]
    sim.has_target[0] = False
    sim._reserve(0)
    sim.status[2] = TAXIING  # evtol_2 on the inbound path, at the arrival altitude
    sim.pos[2] = sim.slot_pos[slot] * [0.85, 0.85, 1.0]
    sim._set_route(2, [sim.slot_pos[slot] * [0.8, 0.8, 1.0]], sim.arrival_alt_m)
    sim._assign_hover_spot(0)
    assert 0 in sim._holding and sim.slot_of[0] == slot and sim.node[0] == -1
    assert sim.reserved[0] == ((*sim.slot_pos[slot, :2], *sim.slot_pos[slot, :2],
                                4.0, 4.0),)
    park(sim, 2, 6)  # evtol_2 gone down to (0, -12): a way in clears
    sim.acting = 1
    sim.step(STAY)
    assert 0 not in sim._holding and sim.node[0] in (3, 5) and sim.slot_of[0] == -1
    assert sim._clear_of_others(sim.reserved[0], 0)


def test_a_reversing_gust_at_a_corner_stays_inside_the_protected_volume():
    sim = make(fleet=1, **{"uncertainty.wind_gust_prob": 1.0,
                           "uncertainty.gust_speed_loss_range": [2.0, 2.0]})
    park(sim, 0, 0)
    sim.step(TAKEOFF)  # every later step a gust reverses the vehicle: it never gets far
    for _ in range(30):
        start = sim.seg_from[0].copy()
        sim.step(sim.single_legal_action(0) or sim.actions.continue_)
        t = sim.target[0]
        u = (t - start) / max(np.linalg.norm(t - start), 1e-9)
        behind = -float((sim.pos[0] - start) @ u)
        assert behind <= sim.margin_m + 1e-9
        assert sim.pos[0, 2] >= sim.park_z_m - 1e-9


def test_an_emergency_landing_comes_down_outside_every_protected_volume():
    sim = make(fleet=2)
    park(sim, 0, 0)  # evtol_0 on port 0 (-6, 0)
    sim._release(1)
    sim.status[1] = TAXIING
    sim.pos[1] = [-5.0, 0.5, 4.0]  # right above it, battery empty
    sim.has_target[1] = True
    sim.target[1] = [0.0, 0.0, 4.0]
    sim.routes[1] = []
    sim.seg_from[1] = sim.pos[1]
    sim._reserve(1)
    sim._take_out_of_service(1)
    assert sim.status[1] == OUT_OF_SERVICE and sim.pos[1, 2] == sim.park_z_m
    assert np.hypot(*(sim.pos[1, :2] - sim.pos[0, :2])) >= sim.clear_h_m
    assert not violations(sim)


def test_masks_are_never_empty_and_every_masked_action_has_a_reason():
    sim = VertiportSim(load_config("paper", **TEN))
    sim.reset(np.random.default_rng(5))
    rng = np.random.default_rng(1)
    kinds = set()
    for _ in range(400):
        for v in range(sim.n):
            mask = sim.action_mask(v)
            assert mask.any()
            reasons = sim.mask_reasons(v)
            assert set(reasons) == set(np.flatnonzero(mask == 0).tolist())
            kinds |= {r.split(":")[0].split(" ")[0] for r in reasons.values()}
        sim.step(int(rng.choice(np.flatnonzero(sim.action_mask(sim.acting)))))
    assert {"status", "occupancy", "separation"} <= kinds


def test_rules_v0_keep_the_old_masks_and_no_reservations():
    sim = make(rules=0)
    fl = sim.cfg.flight
    assert not sim.sep_check and fl.arrival_altitude_m == fl.departure_altitude_m == 8.0
    park(sim, 0, 0)
    park(sim, 1, 3)
    sim.acting = 0
    sim.step(TAKEOFF)
    assert sim.action_mask(1)[node_action(sim, 1)] == 1  # v0 clears the crossing
    assert sim.reserved == [None, None]


# ------------------------------------------------------------------ random play
@pytest.fixture(scope="module")
def shipped_sims():
    made = {(c, trail): VertiportSim(load_config(c, **TEN, **{"atc.trail_departures": trail}))
            for c in SHIPPED for trail in (False, True)}
    yield made
    for sim in made.values():
        sim.close()


@settings(max_examples=18, deadline=None)
@given(config=st.sampled_from(SHIPPED), trail=st.booleans(), seed=st.integers(0, 2**16),
       choices=st.lists(st.integers(0, 10**6), min_size=100, max_size=300))
def test_random_legal_play_never_loses_separation_on_any_shipped_scenario(
        shipped_sims, config, trail, seed, choices):
    """Every shipped scenario at 10 % uncertainty (gusts, charger and take-off failures and
    misreads at 0.1, position noise of std 1 m): no two vehicles within the separation, no
    loss of separation, no contact, after every step (violations() checks all three); with
    and without trailing departures."""
    sim = shipped_sims[config, trail]
    sim.reset(np.random.default_rng(seed))
    for c in choices:
        legal = np.flatnonzero(sim.action_mask(sim.acting))
        reward, _ = sim.step(int(legal[c % len(legal)]))
        problems = violations(sim, reward)
        assert not problems, problems
    assert sim.metrics.separation_losses == 0 and sim.metrics.contacts == 0


def test_simulators_of_one_layout_with_other_fleets_share_the_memos_safely():
    """The memos are shared by every simulator of one geometry in a process (sim/volumes.py);
    the fleet size is not part of the geometry (it sets the holding slots), so a day must not
    depend on the fleets played before it in the process."""
    from agents.controllers.episode import run_aec_episode
    from agents.controllers.registry import make_controller
    from marl_vertiport import vertiport_v1
    from marl_vertiport.sim import volumes

    def day(fleet: int) -> dict:
        env = vertiport_v1.env(config="paper", fleet_size=fleet,
                               **{"schedule.episode_steps": 400})
        try:
            return run_aec_episode(env, make_controller("dispatcher"), seed=3)
        finally:
            env.close()

    volumes._MEMOS.clear()
    alone = day(2)
    volumes._MEMOS.clear()
    day(7)  # seven holding slots on this layout, against five for two vehicles
    after = day(2)
    assert after == alone
    assert alone["completed_trips"] > 0
