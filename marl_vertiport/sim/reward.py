"""The paper's reward of a step, for the eVTOL that acted (eq. 2 and table II):

    R = w_tau * tau + w_gamma * gamma + w_lambda * lambda + w_beta * beta + w_S * S

with every term in ``[-M, +M]`` (``M = reward.term_magnitude``, 5):

* ``tau`` (take-off), on a take-off only: ``+M`` within ``on_time_tolerance_min`` of the
  scheduled time with a battery above ``battery_threshold_pct``, else ``-M``;
* ``gamma`` (landing), on a landing only: ``+M`` no later than the tolerance after the
  scheduled time (earlier is fine) with a battery above the threshold, else ``-M``;
* ``lambda`` (battery): ``M * b / 100`` at a battery ``b >= threshold``, else ``-M``;
* ``beta`` (delay): ``-M + 2M * exp(-delay_min)``, so ``+M`` when on time;
* ``S`` (safety): ``+M`` when the acting vehicle is in a predicted conflict and the action is
  "avoid collision", ``-M`` when it is in one and the action is anything else, 0 otherwise
  (the probe itself is :mod:`marl_vertiport.sim.safety`).

Default weights ``(0.3, 0.3, 0.35, 0.1, 0.35)`` (table II). docs/reward-and-safety.md, section 6.
"""

from __future__ import annotations

import numpy as np

from marl_vertiport.config import RewardConfig, ScheduleConfig

#: Bound on the memo of exp(-delay) (a config with fractional minutes).
_EXP_MEMO_MAX = 4096


class RewardModel:
    """The five terms and their weighted sum; holds no episode state (the memo of
    ``exp(-delay)`` is a cache of a pure function)."""

    def __init__(self, reward: RewardConfig, schedule: ScheduleConfig) -> None:
        self.cfg = reward
        self.magnitude = reward.term_magnitude
        self.tolerance_min = schedule.on_time_tolerance_min
        self._exp_neg_delay: dict[float, float] = {}

    def takeoff(self, now_min: float, scheduled_min: float, battery_pct: float) -> tuple[float, bool]:
        """``(tau, good)`` of a take-off at ``now_min`` scheduled for ``scheduled_min``."""
        good = abs(now_min - scheduled_min) <= self.tolerance_min and battery_pct > self.cfg.battery_threshold_pct
        return (self.magnitude if good else -self.magnitude), bool(good)

    def landing(self, now_min: float, scheduled_min: float, battery_pct: float) -> tuple[float, bool]:
        """``(gamma, good)`` of a landing at ``now_min`` due at ``scheduled_min``."""
        good = now_min <= scheduled_min + self.tolerance_min and battery_pct > self.cfg.battery_threshold_pct
        return (self.magnitude if good else -self.magnitude), bool(good)

    def safety(self, in_conflict: bool, avoided: bool) -> float:
        """``S``: the acting vehicle's conflict flag and whether it chose "avoid collision"."""
        if not in_conflict:
            return 0.0
        return self.magnitude if avoided else -self.magnitude

    def battery(self, battery_pct: float) -> float:
        """``lambda`` at a battery of ``battery_pct``."""
        if battery_pct >= self.cfg.battery_threshold_pct:
            return self.magnitude * battery_pct / 100.0
        return -self.magnitude

    def delay(self, delay_min: float) -> float:
        """``beta`` at a delay of ``delay_min`` (0 when not delayed)."""
        decay = self._exp_neg_delay.get(delay_min)
        if decay is None:
            if len(self._exp_neg_delay) >= _EXP_MEMO_MAX:
                self._exp_neg_delay.clear()
            # numpy's exp, not math's: the two may differ in the last bit.
            decay = self._exp_neg_delay[delay_min] = float(np.exp(-delay_min))
        return -self.magnitude + 2.0 * self.magnitude * decay

    def total(self, tau: float, gamma: float, lam: float, beta: float, safety: float) -> float:
        """The weighted sum of eq. 2."""
        w = self.cfg
        return (w.takeoff_weight * tau + w.landing_weight * gamma + w.battery_weight * lam
                + w.delay_weight * beta + w.safety_weight * safety)
