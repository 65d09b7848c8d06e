"""Action masks per vehicle status, the round-robin turn, the clock, and illegal actions.

Actions of the paper layout (2 normal ports, 1 charging port, 7 hover spots = 10 nodes):
0 stay, 1 take off, 2 + node for nodes 0..9 (ports 0, 1, charger 2, hover spots 3..9),
12 continue, 13 avoid collision: 14 in all.
Seed 0 places (checked in ``new_sim``): evtol_0 on the charger (node 2), evtol_1 on port 1,
evtol_2 on port 0, evtol_3 at hover spot 7: all three ports are taken.
"""

import re

import numpy as np
import pytest

from marl_vertiport import IllegalActionError
from marl_vertiport.config import load_config, with_rules
from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.schema import (
    ARRIVING, AWAY, DEPARTING, HOVERING, ON_CHARGER, ON_PORT, OUT_OF_SERVICE, TAXIING,
)

STAY, TAKEOFF, CONTINUE, AVOID = 0, 1, 12, 13
HOVER_FREE = [5, 6, 7, 8, 10, 11]  # 2 + spots 3, 4, 5, 6, 8, 9 (spot 7 is evtol_3's)


def new_sim(config="paper", seed=0, rules=1, **overrides) -> VertiportSim:
    sim = VertiportSim(with_rules(load_config(config, **overrides), rules))
    sim.reset(np.random.default_rng(seed))
    if seed == 0:
        assert sim.status.tolist() == [ON_CHARGER, ON_PORT, ON_PORT, HOVERING]
        assert sim.node.tolist() == [2, 1, 0, 7]
    return sim


def legal(sim, v) -> list[int]:
    mask = sim.action_mask(v)
    assert mask.dtype == np.int8 and mask.shape == (14,) and mask.sum() >= 1
    return np.flatnonzero(mask).tolist()


def idle(sim):
    v = sim.acting
    return sim.step(STAY if sim.action_mask(v)[STAY] else CONTINUE)


# ------------------------------------------------------------------ masks
def test_masks_at_reset_with_all_ports_taken():
    sim = new_sim()
    assert legal(sim, 0) == [STAY, TAKEOFF]  # on the charger, no free port to move to
    assert legal(sim, 1) == [STAY, TAKEOFF]
    assert legal(sim, 2) == [STAY, TAKEOFF]
    assert legal(sim, 3) == [STAY] + HOVER_FREE  # no port free: only other hover spots


def test_masks_follow_free_and_reserved_nodes():
    """Occupancy alone (rules v0: the separation check of v1 also masks the moves that cross
    the departure, tests/sim/test_clearance.py)."""
    sim = new_sim(rules=0)
    sim.acting = 2
    sim.step(TAKEOFF)  # port 0 is free now
    assert legal(sim, 0) == [STAY, TAKEOFF, 2]
    assert legal(sim, 1) == [STAY, TAKEOFF, 2]
    assert legal(sim, 2) == [CONTINUE, AVOID]  # departing
    assert legal(sim, 3) == [STAY, 2] + HOVER_FREE
    sim.acting = 3
    sim.step(2)  # evtol_3 cleared to land on port 0: reserved for it from now on
    assert sim.node_occupant[0] == 3 and sim.node_occupant[7] == -1
    assert legal(sim, 0) == [STAY, TAKEOFF]
    assert legal(sim, 1) == [STAY, TAKEOFF]
    assert legal(sim, 3) == [CONTINUE, AVOID]  # taxiing


@pytest.mark.parametrize("status, expected", [
    (ON_PORT, [STAY, TAKEOFF]),
    (ON_CHARGER, [STAY, TAKEOFF]),
    (HOVERING, [STAY] + HOVER_FREE),  # its own node 1 is excluded: it holds it
    (TAXIING, [CONTINUE, AVOID]),
    (DEPARTING, [CONTINUE, AVOID]),
    (ARRIVING, [CONTINUE, AVOID]),
    (AWAY, [CONTINUE]),
    (OUT_OF_SERVICE, [STAY]),
])
def test_mask_of_each_status(status, expected):
    sim = new_sim(rules=0)
    sim.status[1] = status  # evtol_1, holding port 1
    assert legal(sim, 1) == expected
    sim = new_sim(rules=1)
    sim.status[1] = status
    if status in (TAXIING, DEPARTING, ARRIVING):  # v1: no route to lift, no avoidance
        expected = [CONTINUE]
    assert legal(sim, 1) == expected


def expected_legal(sim, v) -> list[int]:
    """The mask rules of the paper (no energy check), written out independently of the
    simulator."""
    s, occ, lay = sim.status[v], sim.node_occupant, sim.layout
    if s in (ON_PORT, ON_CHARGER):
        return [STAY, TAKEOFF] + [2 + k for k in range(lay.n_ports) if occ[k] == -1]
    if s == HOVERING:
        return [STAY] + [2 + k for k in range(lay.n_nodes) if occ[k] == -1]
    if s in (TAXIING, DEPARTING, ARRIVING):
        return [CONTINUE, AVOID]
    if s == AWAY:
        return [CONTINUE]
    return [STAY]


@pytest.mark.parametrize("config", ["paper", "paper_uncertain"])
def test_masks_match_the_rules_in_a_random_run(config):
    sim = new_sim(config, seed=4, rules=0, **{"atc.energy_check": False})
    rng = np.random.default_rng(2)
    seen = set()
    for _ in range(300):
        for v in range(sim.n):
            assert legal(sim, v) == expected_legal(sim, v)
            seen.add(int(sim.status[v]))
            if sim.node[v] >= 0:
                assert sim.node_occupant[sim.node[v]] == v  # a node has one holder
        sim.step(int(rng.choice(legal(sim, sim.acting))))
    assert {ON_PORT, HOVERING, TAXIING, DEPARTING, AWAY} <= seen


@pytest.mark.parametrize("config", ["paper", "large"])
def test_single_legal_action_is_the_masks_only_one(config):
    sim = new_sim(config, seed=6)
    rng = np.random.default_rng(3)
    singles = 0
    for _ in range(400):
        for v in range(sim.n):
            legal_now = np.flatnonzero(sim.action_mask(v)).tolist()
            only = sim.single_legal_action(v)
            assert only == (legal_now[0] if len(legal_now) == 1 else None)
            singles += only is not None
        sim.step(int(rng.choice(np.flatnonzero(sim.action_mask(sim.acting)))))
    assert singles > 0


# ------------------------------------------------------------------ turns and clock
def test_round_robin_turns_and_one_minute_per_step():
    sim = new_sim()
    for t in range(13):
        assert sim.acting == t % 4 and sim.minute == t and sim.step_count == t
        _, info = idle(sim)
        assert info["acting_agent"] == f"evtol_{t % 4}" and info["minute"] == t
    assert sim.minute == 13


def make_some_without_decision(sim):
    sim._release(2)
    sim.status[2] = AWAY  # evtol_2 outside the airspace
    sim.physics.make_absent(2)
    sim.battery[3] = 1.0  # evtol_3 hovers: 1 - 2 < 0 -> out of service after the first step


def test_default_turn_waits_for_vehicles_without_decision():
    sim = new_sim()
    make_some_without_decision(sim)
    order = []
    for t in range(8):
        order.append(sim.acting)
        v = sim.acting
        if v == 2:
            assert legal(sim, 2) == [CONTINUE]  # the paper: the turn is spent waiting
        if v == 3 and t > 0:
            assert sim.status[3] == OUT_OF_SERVICE and legal(sim, 3) == [STAY]
        idle(sim)
    assert order == [0, 1, 2, 3, 0, 1, 2, 3]
    assert sim.minute == 8


def test_skip_option_passes_over_away_and_out_of_service():
    sim = new_sim(**{"atc.skip_agents_without_decision": True})
    make_some_without_decision(sim)
    order = []
    for _ in range(6):
        order.append(sim.acting)
        idle(sim)
    # after evtol_1: evtol_2 is away and evtol_3 out of service -> back to evtol_0
    assert order == [0, 1, 0, 1, 0, 1]
    assert sim.minute == 6  # still one minute per step


def test_skip_option_is_plain_round_robin_when_everyone_can_act():
    sim = new_sim(**{"atc.skip_agents_without_decision": True})
    order = []
    for _ in range(6):
        order.append(sim.acting)
        idle(sim)
    assert order == [0, 1, 2, 3, 0, 1]


# ------------------------------------------------------------------ illegal actions
def snapshot(sim):
    return {
        "pos": sim.pos.copy(), "battery": sim.battery.copy(), "minute": sim.minute,
        "status": sim.status.copy(), "node_occupant": sim.node_occupant.copy(),
        "pending_time": sim.pending_time.copy(), "acting": sim.acting,
        "step_count": sim.step_count, "metric_steps": sim.metrics.steps,
        "rng": sim.rng.bit_generator.state,
    }


def assert_same(a, b):
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], np.ndarray):
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        else:
            assert a[key] == b[key], key


ILLEGAL = [2, 4, AVOID, CONTINUE, 14, -1, 99, 1.0, np.float64(0.0), "1", None, True, [1]]


@pytest.mark.parametrize("overrides", [
    {},
    {"uncertainty.action_misread_prob": 1.0, "uncertainty.takeoff_failure_prob": 1.0,
     "uncertainty.wind_gust_prob": 1.0, "uncertainty.charger_failure_prob": 1.0},
], ids=["paper", "all_uncertain"])
@pytest.mark.parametrize("action", ILLEGAL, ids=repr)
def test_illegal_action_raises_and_changes_nothing(action, overrides):
    sim = new_sim(**overrides)
    idle(sim)
    idle(sim)  # evtol_0 and evtol_1 stay: evtol_2 (on port 0, ports full) acts at minute 2
    assert sim.acting == 2 and sim.minute == 2
    before = snapshot(sim)
    with pytest.raises(IllegalActionError) as err:
        sim.step(action)
    assert isinstance(err.value, ValueError)
    msg = str(err.value)
    assert "evtol_2" in msg
    head, _, tail = msg.partition("legal")
    assert f"action {action!r}" in head  # e.g. "action 14", "action '1'", "action None"
    # the legal set of evtol_2: stay (0) and take off (1)
    assert sorted({int(n) for n in re.findall(r"\d+", tail)}) == [STAY, TAKEOFF]
    assert_same(before, snapshot(sim))
    # the sim still works after the refusal
    sim.step(STAY)
    assert sim.minute == 3 and sim.acting == 3


@pytest.mark.parametrize("action", [np.int64(0), np.int8(0), np.array(0), 0])
def test_integer_like_actions_are_accepted(action):
    sim = new_sim()
    _, info = sim.step(action)
    assert info["action"] == STAY and sim.minute == 1
