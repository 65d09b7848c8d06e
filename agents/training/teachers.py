"""The teachers a warm start imitates (``pretrain.teacher``), built by name in each worker.

- ``planner``: the look-ahead planner of :mod:`agents.controllers.planner` (one step of policy
  improvement over the expert dispatcher, simulating each candidate action ``horizon`` steps
  ahead). It plays clearly better than the dispatcher but reads the simulator and spends tens
  of milliseconds a decision; the actor learns to take its decisions from observations alone,
  at a fraction of a millisecond.
- ``guarded_planner``: the planner behind the look-ahead guard of :mod:`agents.controllers.guard`
  (the dispatcher flies the guard's rollouts, with the config's uncertainties): the planner's
  choice stands unless it loses a vehicle where another action loses fewer. A decision the
  guard changes is weighted as one whose wrong choice loses a vehicle (``regret_cap``).
- ``dispatcher``: the expert dispatcher itself.

The names before 0.2.0 (``rollout``, ``guarded_rollout``, ``heuristic``) still load, with a note
(:data:`agents.common.names.RENAMED_TEACHERS`).
"""

from __future__ import annotations

from typing import Any

TEACHERS = ("planner", "guarded_planner", "dispatcher")

#: The planner's options a training config may set (``pretrain.planner_<option>``).
PLANNER_OPTIONS = ("expect_failures", "rescue")


def make_teacher(name: str, planner_horizon: int, planner_margin: float, seed: int,
                 **planner_options: Any):
    """The teacher ``name`` (a name from before 0.2.0 is read as its new name, with a note);
    ``planner_options`` (of :data:`PLANNER_OPTIONS`) go to the planner of ``planner`` and
    ``guarded_planner``."""
    from agents.common.names import RENAMED_TEACHERS, note_renamed
    from agents.controllers.dispatcher import DispatcherController
    from agents.controllers.planner import PlannerController

    if name in RENAMED_TEACHERS:
        note_renamed(name, RENAMED_TEACHERS[name], "pretrain.teacher")
        name = RENAMED_TEACHERS[name]
    unknown = set(planner_options) - set(PLANNER_OPTIONS)
    if unknown:
        raise ValueError(f"planner options {sorted(unknown)}: use some of {PLANNER_OPTIONS}")
    if name == "dispatcher":
        return DispatcherController()
    if name not in TEACHERS:
        raise ValueError(f"teacher {name!r}: use one of {TEACHERS}")
    planner = PlannerController(horizon=planner_horizon, margin=planner_margin, seed=seed,
                                **planner_options)
    if name == "guarded_planner":
        from agents.controllers.guard import GuardController

        return GuardController(proposer=planner, rollout_policy=DispatcherController(), seed=seed)
    return planner
