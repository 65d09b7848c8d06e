"""The paper's uncertainties (case 2, section IV; docs/battery-and-uncertainty.md, section 9), each drawn
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

The draws after the day's first state come in the order the day's decisions call for them, so two
controllers on the same seed meet different luck once their decisions differ. With
``common_random_numbers`` (:class:`KeyedDraws`) every such draw comes instead from a stream keyed
by what it is for, and a given vehicle's k-th take-off, k-th trip, or a given step's gusts and
charger failures draw the same numbers under any controller.
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

    def misread(self, rng: np.random.Generator, action: int, mask: np.ndarray,
                u: np.ndarray | None = None) -> int:
        """The action the vehicle executes: ``action``, or with ``action_misread_prob`` another
        legal one (``mask`` ``(A,)``), uniformly. ``u`` ``(2,)``: uniforms drawn beforehand
        (:class:`KeyedDraws`), used instead of ``rng``."""
        p = self.cfg.action_misread_prob
        if p > 0 and (rng.random() if u is None else u[0]) < p:
            others = np.flatnonzero(mask)
            others = others[others != action]
            if others.size:
                if u is None:
                    return int(others[rng.integers(others.size)])
                return int(others[min(int(u[1] * others.size), others.size - 1)])
        return action

    def takeoff_fails(self, rng: np.random.Generator) -> bool:
        """Whether a take-off fails."""
        p = self.cfg.takeoff_failure_prob
        return bool(p > 0 and rng.random() < p)

    def failed_chargers(self, rng: np.random.Generator, charging_nodes: list[int],
                        u: np.ndarray | None = None) -> list[int]:
        """The charging nodes whose charger fails this step (one draw per charging node; ``u``
        ``(len(charging_nodes),)``: uniforms drawn beforehand, used instead of ``rng``)."""
        p = self.cfg.charger_failure_prob
        if p <= 0:
            return []
        draws = (rng.random(len(charging_nodes)) if u is None else u).tolist()
        return [node for node, draw in zip(charging_nodes, draws) if draw < p]

    def gust_factors(self, rng: np.random.Generator, count: int,
                     u: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[list[float] | None, int]:
        """For ``count`` moving vehicles, the fraction of its step's displacement each keeps
        (``1 - u`` when hit, else 1; ``None`` when gusts are off) and the number of hits.
        ``u``: uniforms drawn beforehand for those vehicles, ``(hit, loss)`` each ``(count,)``,
        used instead of ``rng``."""
        p = self.cfg.wind_gust_prob
        if p <= 0:
            return None, 0
        lo, hi = self.cfg.gust_speed_loss_range
        if u is None:
            hit = rng.random(count) < p
            loss = rng.uniform(lo, hi, count)
        else:
            hit = u[0] < p
            loss = lo + (hi - lo) * u[1]
        return np.where(hit, 1.0 - loss, 1.0).tolist(), int(hit.sum())

    def observed_xy(self, rng: np.random.Generator, xy: np.ndarray,
                    z: np.ndarray | None = None) -> np.ndarray:
        """Observed horizontal positions ``(N, 2)`` of true ones ``xy`` ``(N, 2)``; ``z``
        ``(N, 2)``: standard normals drawn beforehand, used instead of ``rng``."""
        if not self.noisy_observations:
            return xy
        un = self.cfg
        if z is None:
            return xy + rng.normal(un.position_noise_mean_m, un.position_noise_std_m,
                                   size=xy.shape)
        return xy + (un.position_noise_mean_m + un.position_noise_std_m * z)


class KeyedDraws:
    """Common random numbers: the draws of a day after its first state, each from a stream keyed
    by what it is for, so that every controller on the same seed meets the same luck.

    * ``trips[v]``: vehicle ``v``'s flight plans after a landing (the next take-off window, the
      next destination), its k-th trip's draws the same whatever came before;
    * ``takeoffs[v]``: whether vehicle ``v``'s take-off attempts fail, its k-th attempt the same;
    * per step, from one stream, a fixed number of uniforms whatever happens in the step
      (:meth:`begin_step`): two for a misread, one per charging port, two per vehicle for gusts
      (used by the vehicles moving), and with observation noise two standard normals per
      vehicle. Step t's draws are therefore the same under any controller.

    The streams are keyed by a seed drawn once from the env's generator, after the day's first
    state; a look-ahead rolls out its own futures by keying new streams from its own generator
    (:meth:`marl_vertiport.sim.core.VertiportSim.use_generator`).
    """

    def __init__(self, seed: int, n_vehicles: int, n_chargers: int, noisy: bool) -> None:
        self.trips = [np.random.default_rng((seed, 0, v)) for v in range(n_vehicles)]
        self.takeoffs = [np.random.default_rng((seed, 1, v)) for v in range(n_vehicles)]
        self.steps = np.random.default_rng((seed, 2))
        self.n_vehicles, self.n_chargers, self.noisy = n_vehicles, n_chargers, noisy
        self.begin_step()

    @classmethod
    def from_generator(cls, rng: np.random.Generator, n_vehicles: int, n_chargers: int,
                       noisy: bool) -> "KeyedDraws":
        """Streams keyed by one draw of ``rng``."""
        return cls(int(rng.integers(2**63)), n_vehicles, n_chargers, noisy)

    def begin_step(self) -> None:
        """Draw the next step's uniforms (and normals): ``misread_u`` ``(2,)``, ``charger_u``
        ``(n_chargers,)``, ``gust_hit_u`` and ``gust_loss_u`` ``(n_vehicles,)``, ``noise_z``
        ``(n_vehicles, 2)`` or ``None``."""
        n, c = self.n_vehicles, self.n_chargers
        u = self.steps.random(2 + c + 2 * n)
        self.misread_u = u[:2]
        self.charger_u = u[2:2 + c]
        self.gust_hit_u = u[2 + c:2 + c + n]
        self.gust_loss_u = u[2 + c + n:]
        self.noise_z = self.steps.standard_normal((n, 2)) if self.noisy else None

    def __deepcopy__(self, memo: dict) -> "KeyedDraws":
        twin = object.__new__(KeyedDraws)
        for k, v in self.__dict__.items():
            if isinstance(v, np.random.Generator):
                v = twin_generator(v)
            elif isinstance(v, list):
                v = [twin_generator(g) for g in v]
            elif isinstance(v, np.ndarray):
                v = v.copy()
            setattr(twin, k, v)
        return twin


def twin_generator(rng: np.random.Generator) -> np.random.Generator:
    """A generator in the same state as ``rng`` (the same draws from here on)."""
    bits = rng.bit_generator
    twin = np.random.Generator(type(bits)(0))
    twin.bit_generator.state = bits.state
    return twin
