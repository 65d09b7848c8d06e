"""The learned ATC as it is meant to fly: the GCN policy decides, and hands a decision back to
the expert dispatcher where a look-ahead finds a loss near.

:class:`HandbackController` is the look-ahead guard (:mod:`agents.controllers.guard`) around a
GCN checkpoint, with the dispatcher flying the rollouts and the settings that hand decisions
back to it (docs/controllers.md, docs/training.md, "Handing decisions back"):

* ``defer_pct=30``: a vehicle with less than 30 % charge is decided by the dispatcher;
* ``margin_pct=25``: the policy's choice stands only if none of its rollouts (the dispatcher
  flying the fleet for two hours, with the config's gusts and failures) loses a vehicle or lets a
  live vehicle's charge fall below 25 %; otherwise the dispatcher's choice is checked and taken;
* ``quiet_pct=101``: every decision with a choice is checked;
* ``reward_margin=0``: where the policy's choice passes its check but the dispatcher disagrees,
  the dispatcher's choice is rolled out with the same draws and taken if it loses no vehicle and
  earns at least as much reward on average (chosen on validation days over a margin of 10, which
  is below the dispatcher on ``fleet40`` and behind no margin in case 1, on ``mid`` and on
  ``large``; docs/training.md, "Letting the rollouts choose").

``self_check`` (off) would also roll the policy itself out; on the validation days the settings
were chosen on it lost as many vehicles and cost twice the time (docs/training.md).

It reads the simulator and simulates, so it is a model-based controller: decision-time search
with the learned policy as its prior, not a policy that acts from the observation alone. Every
argument of the guard may be changed in a spec (``handback[base=runs/train/x/model_59.pt]``,
``handback[self_check=true]``).
"""

from __future__ import annotations

from typing import Any

from agents.controllers.guard import GuardedController

#: The settings that make the guard the handed-back learned ATC (chosen on validation days:
#: the first four on 800 060 to 800 079, ``reward_margin`` on validation days of case 1, case 2,
#: 10 %, ``mid``, ``large`` and ``fleet40`` from 800 100; docs/training.md).
HANDBACK_SETTINGS = {"fleet": "heuristic", "defer_pct": 30.0, "margin_pct": 25.0,
                     "quiet_pct": 101.0, "reward_margin": 0.0}


class HandbackController(GuardedController):
    """The GCN policy (``base``, default the shipped checkpoint ``gcn``), handed back to the
    dispatcher near a loss: :class:`~agents.controllers.guard.GuardedController` with
    :data:`HANDBACK_SETTINGS` as its defaults (every argument of the guard is accepted)."""

    name = "handback"

    def __init__(self, base: str | Any = "gcn", **kwargs: Any) -> None:
        super().__init__(base=base, **{**HANDBACK_SETTINGS, **kwargs})
