"""The guard's ``floor_pct``: a vehicle whose charge falls below the floor in a rollout, having
started it at or above, counts as lost there; a vehicle already below counts only if lost."""

import numpy as np
import pytest

from agents.controllers.guard import GuardController
from agents.controllers.planner import roll_out
from agents.controllers.registry import make_controller
from helpers import dispatcher_decision
from marl_vertiport import vertiport_v1
from marl_vertiport.sim.schema import HOVERING, ON_CHARGER, ON_PORT


def _counted_by_hand(guard, sim, action: int, floor_pct: float) -> int:
    """One nominal rollout of ``action``, the dispatcher flying: the vehicles lost in it, plus
    those that started at or above ``floor_pct`` and fell below it while live."""
    least = np.where(sim.lost, np.inf, sim.battery).astype(float)

    def watch(s):
        np.minimum(least, np.where(s.lost, np.inf, s.battery), out=least)

    start = sim.battery.copy()
    roll_out(guard._scratch, guard._builder, guard.rollout_policy, sim.snapshot(), action,
             guard.horizon_steps(sim), None, watch)
    lost = guard._scratch.lost & ~sim.lost
    fell = ~sim.lost & (start >= floor_pct) & (least < floor_pct)
    return int(np.count_nonzero(lost | fell))


def test_floor_pct_is_validated_and_parsed():
    with pytest.raises(ValueError, match="floor_pct"):
        GuardController(floor_pct=-1.0)
    with pytest.raises(ValueError, match="floor_pct"):
        GuardController(floor_pct=101.0)
    guard = make_controller("lookahead[floor_pct=15]")
    assert guard.settings.floor_pct == 15.0
    guard.close()
    default = GuardController()
    assert default.settings.floor_pct == 0.0
    default.close()


def test_the_floor_counts_the_vehicles_that_fall_below_it_as_lost():
    """At a busy decision the floor sits between the fleet's charges, so that some vehicles
    start below it (counted only if lost) and others fall below it (counted); every legal
    action's count matches a rollout counted by hand, and without a floor only losses count."""
    env = vertiport_v1.env(config="paper")
    *_, legal = dispatcher_decision(env, lambda sim, obs, legal, choice: (
        sim.step_count >= 300 and len(legal) >= 2
        and sim.status[sim.acting] in (ON_PORT, ON_CHARGER, HOVERING)))
    sim = env.unwrapped.sim
    live = sim.battery[~sim.lost]
    floor_pct = float(np.median(live)) + 0.5
    assert (live < floor_pct).any() and (live >= floor_pct).any()
    guard = GuardController(nominal=True, floor_pct=floor_pct)
    plain = GuardController(nominal=True)
    for g in (guard, plain):
        g.reset(seed=0)
        g.bind(sim)
    values, _ = guard.evaluate(sim, legal)
    plain_values, _ = plain.evaluate(sim, legal)
    counts = {a: _counted_by_hand(guard, sim, a, floor_pct) for a in legal}
    losses = {a: _counted_by_hand(plain, sim, a, 0.0) for a in legal}
    assert {a: values[a][0] for a in legal} == counts
    assert {a: plain_values[a][0] for a in legal} == losses
    assert any(counts[a] > losses[a] for a in legal)  # the floor counts near losses
    assert all(values[a][1:] == plain_values[a][1:] for a in legal)  # reward, margin unchanged
    for g in (guard, plain):
        g.close()
    env.close()
