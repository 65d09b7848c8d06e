"""The learned ATC as shipped: a look-ahead search around a proposer, the GCN policy by default.

:class:`LookaheadController` is the look-ahead of :mod:`agents.controllers.guard` with the
``lookahead`` preset (:mod:`agents.controllers.lookahead_settings`) and the dispatcher as its
rollout policy. At every decision with a choice it rolls the proposer's choice out four times
for two hours, the dispatcher flying the fleet, with the config's gusts and failures:

* a vehicle under 30 % charge is decided by the dispatcher (``defer_pct=30``);
* the proposer's choice stands only if none of its rollouts loses a vehicle or lets a live
  vehicle's charge fall below 25 % (``margin_pct=25``); otherwise the dispatcher's choice is
  checked and taken;
* where the proposer's choice passes and the dispatcher disagrees, the dispatcher's choice is
  rolled out with the same draws and taken if it loses no vehicle and earns at least as much
  reward on average (``reward_margin=0``): the rollouts choose between two candidates.

The proposer is a parameter: ``lookahead`` (the shipped policy, ``gcn``),
``lookahead[proposer=runs/train/x/model_59.pt]``, ``lookahead[proposer=fcfs]`` (the same
search with a rule where the policy was: the control of any claim about what learning adds).

It reads the simulator and simulates, so it is a model-based controller: decision-time search
with the proposer as its prior, not a policy that acts from the observation alone. Every
setting may be changed in a spec (``lookahead[samples=8]``, ``lookahead[self_check=true]``).
"""

from __future__ import annotations

from typing import Any

from agents.controllers.guard import GuardController

__all__ = ["HandbackController", "LookaheadController"]


class LookaheadController(GuardController):
    """The proposer (default: the shipped checkpoint ``gcn``) inside the look-ahead, the
    dispatcher flying the rollouts: :class:`~agents.controllers.guard.GuardController` with the
    ``lookahead`` preset. Takes every argument of the guard."""

    name = "lookahead"
    preset = "lookahead"
    default_proposer: Any = "gcn"
    default_rollout_policy: Any = "dispatcher"


#: The class's name before 0.2.0.
HandbackController = LookaheadController
