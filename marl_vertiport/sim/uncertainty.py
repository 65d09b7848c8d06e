"""The paper's uncertainties (case 2, section IV; docs/environment.md, section 9), each drawn
from the env's one seeded generator in a fixed order, so an episode is reproducible from its
seed and actions:

* **wind gusts**: each vehicle following a route is hit with probability ``wind_gust_prob`` per
  step; a hit takes a fraction ``u ~ U(gust_speed_loss_range)`` of the step's displacement away
  (``u = 1`` stops it, ``u = 2`` reverses it);
* **charger failures**: each charging port fails for the step with probability
  ``charger_failure_prob`` (its vehicle idles instead of charging);
* **take-off failures**: a take-off fails with probability ``takeoff_failure_prob`` (the vehicle
  stays on its port);
* **observation noise** (paper draft): observed x and y of every vehicle get
  ``N(position_noise_mean_m, position_noise_std_m)`` metres of error;
* **action misreads** (paper draft): with probability ``action_misread_prob`` the commanded
  action is replaced by another legal one, drawn uniformly.

A probability of 0 draws nothing, so turning one effect on leaves the others' draws unchanged.
"""

from __future__ import annotations

import numpy as np

from marl_vertiport.config import UncertaintyConfig


class Uncertainty:
    """The draws of the uncertainties of one config."""

    def __init__(self, uncertainty: UncertaintyConfig) -> None:
        self.cfg = uncertainty
        #: Whether observed positions carry noise.
        self.noisy_observations = (uncertainty.position_noise_std_m > 0
                                   or uncertainty.position_noise_mean_m != 0)

    def misread(self, rng: np.random.Generator, action: int, mask: np.ndarray) -> int:
        """The action the vehicle executes: ``action``, or with ``action_misread_prob`` another
        legal one (``mask`` ``(A,)``), uniformly."""
        p = self.cfg.action_misread_prob
        if p > 0 and rng.random() < p:
            others = np.flatnonzero(mask)
            others = others[others != action]
            if others.size:
                return int(others[rng.integers(others.size)])
        return action

    def takeoff_fails(self, rng: np.random.Generator) -> bool:
        """Whether a take-off fails."""
        p = self.cfg.takeoff_failure_prob
        return bool(p > 0 and rng.random() < p)

    def failed_chargers(self, rng: np.random.Generator, charging_nodes: list[int]) -> list[int]:
        """The charging nodes whose charger fails this step (one draw per charging node)."""
        p = self.cfg.charger_failure_prob
        if p <= 0:
            return []
        draws = rng.random(len(charging_nodes)).tolist()
        return [node for node, u in zip(charging_nodes, draws) if u < p]

    def gust_factors(self, rng: np.random.Generator, count: int) -> tuple[list[float] | None, int]:
        """For ``count`` moving vehicles, the fraction of its step's displacement each keeps
        (``1 - u`` when hit, else 1; ``None`` when gusts are off) and the number of hits."""
        p = self.cfg.wind_gust_prob
        if p <= 0:
            return None, 0
        lo, hi = self.cfg.gust_speed_loss_range
        hit = rng.random(count) < p
        loss = rng.uniform(lo, hi, count)
        return np.where(hit, 1.0 - loss, 1.0).tolist(), int(hit.sum())

    def observed_xy(self, rng: np.random.Generator, xy: np.ndarray) -> np.ndarray:
        """Observed horizontal positions ``(N, 2)`` of true ones ``xy`` ``(N, 2)``."""
        if not self.noisy_observations:
            return xy
        un = self.cfg
        return xy + rng.normal(un.position_noise_mean_m, un.position_noise_std_m, size=xy.shape)
