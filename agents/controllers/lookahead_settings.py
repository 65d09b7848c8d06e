"""The settings of the look-ahead around a proposer (:mod:`agents.controllers.guard`): how far
and how often it simulates, when it overrides the proposer, when it hands a decision to its
rollout policy. One frozen dataclass, checked when it is made, and two named presets:

* ``guard``: veto only. The proposer decides; the look-ahead changes a choice only where its
  rollouts lose a vehicle and another legal action loses fewer (``guard``).
* ``lookahead``: the learned ATC as shipped (``lookahead``): every decision with a choice is
  checked (``quiet_pct=101``), a vehicle under 30 % charge is decided by the rollout policy
  (``defer_pct``), a choice whose rollouts let a vehicle fall under 25 % is handed to it too
  (``margin_pct``), and where the proposer's clean choice and the rollout policy's differ, the
  rollouts choose between them (``reward_margin=0``). Chosen on validation days (the first
  three on 800 060 to 800 079, ``reward_margin`` on days from 800 100;
  experiments/lookahead-around-policy-rules-v1, experiments/lookahead-reward-margin).

A spec changes any field by name: ``'guard[horizon_min=60,samples=8]'``,
``'lookahead[reward_margin=10]'``; in Python, ``LookaheadSettings.preset("lookahead").replace(
samples=8)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from typing import Any

__all__ = ["LookaheadSettings", "PREFERRED_COLUMN", "PRESETS"]

#: What ``prefer`` may name, and the column of the look-ahead's values (lost, reward, least
#: charge) it maximises among the actions that lose the fewest vehicles.
PREFERRED_COLUMN = {"reward": 1, "margin": 2}


@dataclass(frozen=True)
class LookaheadSettings:
    """How the look-ahead simulates and decides (module docstring; every charge in %, every
    time in minutes of the day).

    The fields that hand decisions to the rollout policy (``defer_pct``, ``margin_pct``,
    ``self_check``, ``reward_margin``) need a rollout policy other than the proposer; the
    controller checks that (:meth:`check_rollout_policy`)."""

    horizon_min: float = 120.0
    """Minutes simulated per rollout, the decision's own step included."""
    samples: int = 4
    """Rollouts per action; each draws the config's uncertainties from a generator of its own
    (one rollout where the config has none)."""
    compare_samples: int | None = None
    """Rollouts per action where the proposer's choice lost a vehicle and every legal action is
    compared (at least ``samples``; ``None``: ``samples``)."""
    nominal: bool = False
    """Roll out without the config's uncertainties (and so once per action)."""
    quiet_pct: float = 20.0
    """A clean check in which every live vehicle keeps at least this charge skips the checks of
    the next ``quiet_min`` minutes (above 100: never skip)."""
    quiet_min: float = 10.0
    """Minutes of skipped checks after a quiet check."""
    seed: int = 0
    """Seed of the rollouts' generators, combined with the episode's seed, the step and the
    sample."""
    min_lost: float = 0.5
    """Vehicles the proposer's choice must lose on average over its rollouts to be changed."""
    clairvoyant: bool = False
    """Roll out once per action from a copy of the env's own generator: an oracle that sees the
    day's future, for studies; not with ``nominal``."""
    prefer: str = "reward"
    """Of the actions that lose the fewest vehicles, take the one whose rollouts earn the most
    reward (``"reward"``) or keep the most charge (``"margin"``)."""
    defer_pct: float = 0.0
    """An acting vehicle with less charge than this is decided by the rollout policy (0:
    never)."""
    margin_pct: float = 0.0
    """A checked choice whose rollouts lose a vehicle or let a live vehicle fall below this
    charge is handed to the rollout policy, then checked as usual (0: never)."""
    self_check: bool = False
    """A proposer's choice that passes the rollout policy's rollouts stands only if ``samples``
    rollouts in which the proposer goes on deciding lose no vehicle either."""
    min_saved: float = 0.0
    """An override must lose at least this many vehicles fewer on average (0: any fewer)."""
    override_takeoff: bool = True
    """Whether an override may take off where the proposer's choice does not."""
    floor_pct: float = 0.0
    """A live vehicle whose charge falls below this in a rollout, having started it at or above,
    counts as lost in that rollout (0: only a depleted battery is a loss)."""
    port_hops: bool = True
    """Whether a vehicle on a normal port may taxi to another normal port."""
    reward_margin: float | None = None
    """Where the proposer's choice passes its check and the rollout policy's differs, the
    latter is taken if its rollouts (the same draws) lose no vehicle and earn at least this
    much more reward on average (``None``: never). In the wide search, what another candidate
    must earn over the rollout policy's choice (``None``: any more)."""
    candidates: int = 0
    """The wide search (:mod:`agents.controllers.search`): at each decision that matters, roll
    out the rollout policy's choice and the proposer's ``candidates`` most probable legal
    actions (every legal one where the proposer has no probabilities, or where ``candidates``
    is at least their number) with the same draws, and take the one that loses the fewest
    vehicles, then earns the most; it takes the place of ``defer_pct`` and ``margin_pct`` (0:
    the two-candidate look-ahead above)."""
    leaf_turns: float = 0.0
    """Add to each rollout's reward the value of its end state: each vehicle's battery and delay
    terms held for this many more turns of its own, a vehicle out of service earning the worst
    (:func:`~agents.controllers.planner.held_terms_value`, the planner's terminal value; 0:
    none)."""
    confidence: float = 0.0
    """In the wide search: a candidate replaces the rollout policy's choice only where its
    paired gain over it (reward, less :data:`~agents.controllers.search.LOSS_COST` per vehicle
    lost, rollout by rollout on the same draws) has a mean at least ``confidence`` standard
    errors above ``reward_margin`` (0: the means decide, losses first)."""

    def __post_init__(self) -> None:
        if self.horizon_min <= 0:
            raise ValueError(f"horizon_min must be > 0 minutes, got {self.horizon_min}")
        if self.samples < 1:
            raise ValueError(f"samples must be >= 1, got {self.samples}")
        if self.compare_samples is not None and self.compare_samples < self.samples:
            raise ValueError(f"compare_samples must be >= samples ({self.samples}), "
                             f"got {self.compare_samples}")
        if self.quiet_min < 0:
            raise ValueError(f"quiet_min must be >= 0 minutes, got {self.quiet_min}")
        if self.min_lost <= 0:
            raise ValueError(f"min_lost must be > 0 vehicles, got {self.min_lost}")
        if self.min_saved < 0:
            raise ValueError(f"min_saved must be >= 0 vehicles, got {self.min_saved}")
        if self.clairvoyant and self.nominal:
            raise ValueError("clairvoyant rollouts draw the env's own future: they cannot also "
                             "be nominal (without the config's uncertainties)")
        if self.candidates < 0:
            raise ValueError(f"candidates must be >= 0, got {self.candidates}")
        if self.leaf_turns < 0:
            raise ValueError(f"leaf_turns must be >= 0 turns, got {self.leaf_turns}")
        if self.confidence < 0:
            raise ValueError(f"confidence must be >= 0 standard errors, got {self.confidence}")
        if self.prefer not in PREFERRED_COLUMN:
            raise ValueError(f"prefer must be one of {sorted(PREFERRED_COLUMN)}, "
                             f"got {self.prefer!r}")
        for name in ("defer_pct", "margin_pct", "floor_pct"):
            if not 0.0 <= getattr(self, name) <= 100.0:
                raise ValueError(f"{name} must be a charge in [0, 100] %, "
                                 f"got {getattr(self, name)}")

    @classmethod
    def preset(cls, name: str) -> LookaheadSettings:
        """The preset ``name`` (:data:`PRESETS`)."""
        if name not in PRESETS:
            raise ValueError(f"look-ahead preset {name!r}: use one of {sorted(PRESETS)}")
        return PRESETS[name]

    def replace(self, **changes: Any) -> LookaheadSettings:
        """A copy with ``changes``; an unknown name raises ``TypeError`` naming it."""
        known = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise TypeError(f"unexpected look-ahead setting(s) {', '.join(map(repr, unknown))}; "
                            f"known: {', '.join(sorted(known))}")
        return dataclasses.replace(self, **changes)

    def check_rollout_policy(self, has_own: bool) -> None:
        """Raise ``ValueError`` where a field hands decisions to the rollout policy and there is
        none but the proposer (``has_own`` False)."""
        if has_own:
            return
        example = "guard[proposer=gcn,rollout_policy=dispatcher,{}]"
        for name in ("defer_pct", "margin_pct"):
            if getattr(self, name) > 0:
                raise ValueError(f"{name} hands decisions to the rollout policy: it needs a "
                                 f"rollout_policy of its own (e.g. "
                                 f"{example.format(name + '=30')})")
        if self.reward_margin is not None:
            raise ValueError("reward_margin weighs the proposer's choice against the rollout "
                             "policy's: it needs a rollout_policy of its own (e.g. "
                             f"{example.format('reward_margin=0')})")
        if self.self_check:
            raise ValueError("self_check rolls the proposer out beside the rollout policy: it "
                             "needs a rollout_policy of its own (e.g. "
                             f"{example.format('self_check=true')})")


#: The named presets (module docstring).
PRESETS = {
    "guard": LookaheadSettings(),
    "lookahead": LookaheadSettings(defer_pct=30.0, margin_pct=25.0, quiet_pct=101.0,
                                   reward_margin=0.0),
}
