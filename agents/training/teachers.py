"""The teachers a warm start imitates (``pretrain.teacher``), built by name in each worker.

- ``rollout``: the look-ahead planner of :mod:`agents.controllers.planner` (one step of policy
  improvement over the expert dispatcher, simulating each candidate action ``horizon`` steps
  ahead). It plays clearly better than the dispatcher but reads the simulator and spends tens
  of milliseconds a decision; the actor learns to take its decisions from observations alone,
  at a fraction of a millisecond.
- ``guarded_rollout``: the planner behind the look-ahead guard of :mod:`agents.controllers.guard`
  (the dispatcher flies the guard's rollouts, with the config's uncertainties): the planner's
  choice stands unless it loses a vehicle where another action loses fewer. A decision the
  guard changes is weighted as one whose wrong choice loses a vehicle (``regret_cap``).
- ``heuristic``: the expert dispatcher itself.
"""

from __future__ import annotations

from typing import Any

TEACHERS = ("rollout", "guarded_rollout", "heuristic")

#: The planner's options a training config may set (``pretrain.rollout_<option>``).
PLANNER_OPTIONS = ("expect_failures", "rescue")


def make_teacher(name: str, rollout_horizon: int, rollout_margin: float, seed: int,
                 **planner_options: Any):
    """The teacher ``name``; ``planner_options`` (of :data:`PLANNER_OPTIONS`) go to the planner
    of ``rollout`` and ``guarded_rollout``."""
    from agents.controllers.dispatcher import DispatcherController
    from agents.controllers.planner import RolloutPlanner

    unknown = set(planner_options) - set(PLANNER_OPTIONS)
    if unknown:
        raise ValueError(f"planner options {sorted(unknown)}: use some of {PLANNER_OPTIONS}")
    if name == "heuristic":
        return DispatcherController()
    if name not in TEACHERS:
        raise ValueError(f"teacher {name!r}: use one of {TEACHERS}")
    planner = RolloutPlanner(horizon=rollout_horizon, margin=rollout_margin, seed=seed,
                             **planner_options)
    if name == "guarded_rollout":
        from agents.controllers.guard import GuardedController

        return GuardedController(base=planner, fleet=DispatcherController(), seed=seed)
    return planner
