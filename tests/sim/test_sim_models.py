"""Unit tests of the simulator's paper concepts, one class per module, on hand-computed cases:
the reward (eq. 2), the battery model (eq. 1), the schedule windows and delays, the conflict
probe (eqs. 3-5) and the uncertainty draws. The same rules run inside full episodes in
test_reward.py, test_schedule_battery.py and test_invariants.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from marl_vertiport.config import BatteryConfig, RewardConfig, ScheduleConfig, UncertaintyConfig
from marl_vertiport.sim.battery import BatteryModel
from marl_vertiport.sim.geometry import cpa, segment_distance
from marl_vertiport.sim.reward import RewardModel
from marl_vertiport.sim.safety import conflicting_pairs, planned_velocity, swept_distances_m
from marl_vertiport.sim.schedule import FlightSchedule
from marl_vertiport.sim.schema import (
    DELAYED, EARLY, NO_OPERATION, ON_CHARGER, ON_PORT, ON_TIME, PENDING_LANDING, PENDING_TAKEOFF,
    STATUS_NAMES, Status,
)
from marl_vertiport.sim.uncertainty import Uncertainty

AIRBORNE = (False, False, True, True, True, True, True, False)


class TestReward:
    model = RewardModel(RewardConfig(), ScheduleConfig())

    def test_takeoff_and_landing_terms(self):
        assert self.model.takeoff(20.0, 15.0, 80.0) == (5.0, True)       # 5 min late: on time
        assert self.model.takeoff(21.0, 15.0, 80.0) == (-5.0, False)     # 6 min late
        assert self.model.takeoff(9.0, 15.0, 80.0) == (-5.0, False)      # 6 min early
        assert self.model.takeoff(15.0, 15.0, 30.0) == (-5.0, False)     # battery not above 30
        assert self.model.landing(2.0, 15.0, 80.0) == (5.0, True)        # early is fine
        assert self.model.landing(21.0, 15.0, 80.0) == (-5.0, False)

    def test_battery_delay_safety_and_weights(self):
        assert self.model.battery(30.0) == pytest.approx(1.5)
        assert self.model.battery(29.9) == -5.0
        assert self.model.delay(0.0) == 5.0
        assert self.model.delay(6.0) == pytest.approx(-5.0 + 10.0 * math.exp(-6.0))
        assert self.model.safety(False, True) == 0.0
        assert self.model.safety(True, True) == 5.0 and self.model.safety(True, False) == -5.0
        # Table II weights (0.3, 0.3, 0.35, 0.1, 0.35): a good take-off at 80 % with no delay,
        # in a conflict it did not avoid.
        assert self.model.total(5.0, 0.0, 4.0, 5.0, -5.0) == pytest.approx(
            0.3 * 5 + 0.35 * 4 + 0.1 * 5 - 0.35 * 5)


class TestBattery:
    model = BatteryModel(BatteryConfig(), AIRBORNE, ON_PORT, ON_CHARGER)

    def test_rates_by_status(self):
        # on port -4, on charger +10, airborne -2 (hovering), out of service 0
        assert self.model.rate_pct == (-4.0, 10.0, -2.0, -2.0, -2.0, -2.0, -2.0, 0.0)

    def test_cruise_hover_failed_charger_and_clipping(self):
        status = [Status.TAXIING, Status.HOVERING, Status.ON_CHARGER, Status.ON_CHARGER, Status.ON_PORT]
        change = self.model.changes([50.0] * 5, [int(s) for s in status], [(0, 2.0), (1, 0.5)],
                                    failed_charging=[3])
        # 0.5 %/m x 0.25 (rules v1's calibration) x 2 m; 0.5 m is hovering
        assert change == [-0.25, -2.0, 10.0, -4.0, -4.0]
        assert self.model.apply([0.2, 50.0, 95.0, 3.0, 2.0], change) == [0.0, 48.0, 100.0, 0.0, 0.0]

    def test_rules_v0_charge_the_papers_full_drain(self):
        v0 = BatteryModel(BatteryConfig(cruise_drain_scale=1.0), AIRBORNE, ON_PORT, ON_CHARGER)
        assert v0.changes([50.0], [int(Status.TAXIING)], [(0, 2.0)]) == [-1.0]  # 0.5 %/m x 2 m


class TestSchedule:
    schedule = FlightSchedule(ScheduleConfig())

    def test_windows_and_draws(self):
        rng = np.random.default_rng(0)
        first = self.schedule.initial_takeoffs_min(rng, 500)
        assert first.min() == 5 and first.max() == 20
        assert self.schedule.first_landing_min() == 15
        assert self.schedule.landing_min(100.0) == 115.0
        after = {self.schedule.takeoff_after_landing_min(rng, 100.0) for _ in range(300)}
        assert after == set(range(110, 121))

    def test_delay_status_and_lateness(self):
        pending_time = np.array([10.0, 10.0, 10.0, 30.0, 30.0])
        kind = [PENDING_TAKEOFF, PENDING_LANDING, NO_OPERATION, PENDING_TAKEOFF, PENDING_LANDING]
        out = np.zeros(5)
        delays = self.schedule.delays_min(20.0, pending_time, kind, out)
        assert delays[:3] == [10.0, 10.0, 0.0] and out.tolist() == [10, 10, 10, -10, -10]
        codes = self.schedule.status_codes(20.0, pending_time, np.array(kind))
        assert codes.tolist() == [DELAYED, DELAYED, ON_TIME, EARLY, ON_TIME]  # early landing: on time
        assert [self.schedule.status_code(r, k) for r, k in zip(out.tolist(), kind)] == codes.tolist()
        assert self.schedule.lateness_min(16.0, 10.0) == 6.0
        assert self.schedule.lateness_min(15.0, 10.0) == 0.0


class TestSafety:
    def test_head_on_paths_conflict_and_parallel_or_separated_ones_do_not(self):
        start = {0: (0.0, 0.0), 1: (10.0, 0.0), 2: (0.0, 10.0)}
        end = {0: (10.0, 0.0), 1: (0.0, 0.0), 2: (10.0, 10.0)}
        vel = {v: planned_velocity(start[v], end[v], 8.0) for v in start}
        assert vel[0] == (8.0, 0.0) and vel[1] == (-8.0, 0.0)
        # 0 and 1 meet head on (t_min = 10/16 s, D_min = 0); 2 flies parallel 10 m away.
        assert conflicting_pairs([0, 1, 2], start, end, vel, [8.0, 8.0, 8.0], 3.0) == [(0, 1)]
        # Legs 3 m or more apart in altitude never conflict.
        assert conflicting_pairs([0, 1], start, end, vel, [8.0, 12.0, 8.0], 3.0) == []

    def test_closest_approach_in_the_past_is_no_conflict(self):
        start = {0: (5.0, 0.0), 1: (4.0, 0.0)}   # already passed each other, moving apart
        end = {0: (10.0, 0.0), 1: (0.0, 0.0)}
        vel = {v: planned_velocity(start[v], end[v], 8.0) for v in start}
        assert conflicting_pairs([0, 1], start, end, vel, [8.0, 8.0], 3.0) == []

    @settings(max_examples=200, deadline=None)
    @given(st.lists(st.tuples(st.integers(-20, 20), st.integers(-20, 20), st.integers(-20, 20),
                              st.integers(-20, 20), st.sampled_from([8.0, 10.0, 12.0])),
                    min_size=2, max_size=7))
    def test_the_probe_is_its_definition(self, legs):
        """conflicting_pairs (its closest approach inline, tested before the paths) gives the
        pairs that eqs. 3-4 and the path distance give, on a 2 m grid of legs."""
        start = {v: (2.0 * x0, 2.0 * y0) for v, (x0, y0, _, _, _) in enumerate(legs)}
        end = {v: (2.0 * x1, 2.0 * y1) for v, (_, _, x1, y1, _) in enumerate(legs)}
        alt = [z for *_, z in legs]
        vel = {v: planned_velocity(start[v], end[v], 8.0) for v in start}
        sep = 4.0
        expect = []
        for a in range(len(legs)):
            for b in range(a + 1, len(legs)):
                t, d = cpa([start[a][0] - start[b][0], start[a][1] - start[b][1]],
                           [vel[a][0] - vel[b][0], vel[a][1] - vel[b][1]])
                if (abs(alt[a] - alt[b]) < sep and t >= 0.0 and d <= sep
                        and segment_distance(start[a], end[a], start[b], end[b]) < sep):
                    expect.append((a, b))
        assert conflicting_pairs(list(range(len(legs))), start, end, vel, alt, sep) == expect

    def test_swept_distance_sees_a_crossing_within_the_step(self):
        prev = np.array([[0.0, 0.0, 8.0], [10.0, 0.0, 8.0]])
        now = np.array([[10.0, 0.0, 8.0], [0.0, 0.0, 8.0]])  # they cross mid-step
        assert swept_distances_m(prev, now, [(0, 1)]) == [pytest.approx(0.0)]
        many = [(0, 1)] * 30  # the array path gives the same
        assert swept_distances_m(prev, now, many) == pytest.approx([0.0] * 30)


class TestUncertainty:
    def test_off_draws_nothing(self):
        off = Uncertainty(UncertaintyConfig())
        rng = np.random.default_rng(1)
        before = rng.bit_generator.state
        mask = np.array([1, 1, 0, 1])
        assert off.misread(rng, 0, mask) == 0 and not off.takeoff_fails(rng)
        assert off.failed_chargers(rng, [3, 4]) == [] and off.gust_factors(rng, 3) == (None, 0)
        xy = np.ones((2, 2))
        assert off.observed_xy(rng, xy) is xy
        assert rng.bit_generator.state == before

    def test_certain_effects_and_their_ranges(self):
        on = Uncertainty(UncertaintyConfig(wind_gust_prob=1.0, charger_failure_prob=1.0,
                                           takeoff_failure_prob=1.0, action_misread_prob=1.0,
                                           position_noise_mean_m=1.0, position_noise_std_m=0.5))
        rng = np.random.default_rng(2)
        mask = np.array([1, 1, 0, 1])
        assert all(on.misread(rng, 0, mask) in (1, 3) for _ in range(20))  # another legal one
        assert on.misread(rng, 0, np.array([1, 0, 0, 0])) == 0             # no other choice
        assert on.takeoff_fails(rng) and on.failed_chargers(rng, [3, 4]) == [3, 4]
        keep, hits = on.gust_factors(rng, 1000)
        assert hits == 1000 and -1.0 <= min(keep) and max(keep) <= 0.8  # 1 - U(0.2, 2.0)
        noisy = on.observed_xy(rng, np.zeros((4000, 2)))
        assert abs(noisy.mean() - 1.0) < 0.05 and abs(noisy.std() - 0.5) < 0.05


def test_status_codes_are_one_enum():
    assert [s.value for s in Status] == list(range(8))
    assert STATUS_NAMES[Status.HOVERING] == "hovering" and STATUS_NAMES[-1] == "out_of_service"
