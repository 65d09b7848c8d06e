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
- ``search``: the wide look-ahead search of :mod:`agents.controllers.search` over every legal
  action, the dispatcher flying its rollouts, four samples of the config's gusts and failures
  each over two hours, every candidate meeting the same draws: the teacher that knows the
  uncertainty the planner's nominal model leaves out. Its candidates' values (reward less 1 000
  per vehicle lost) weight the decisions (``regret_cap``), and a decision where one candidate
  loses a vehicle another keeps weighs as one that loses a vehicle.
- ``lookahead``: the learned ATC's own look-ahead (:mod:`agents.controllers.lookahead`, the
  shipped preset) around the learner: the actor being fit proposes, and its choice stands
  unless the rollouts (the dispatcher flying, the config's gusts and failures, common random
  numbers) hand the decision to the dispatcher. Each round's teacher is built on that round's
  learner, so a better policy makes a better teacher (expert iteration); without a learner
  (behaviour cloning with no ``init_checkpoint``) the dispatcher proposes. See
  :class:`LookaheadTeacher` for what a decision weighs.
- ``dispatcher``: the expert dispatcher itself.

The names before 0.2.0 (``rollout``, ``guarded_rollout``, ``heuristic``) still load, with a note
(:data:`agents.common.names.RENAMED_TEACHERS`).
"""

from __future__ import annotations

from typing import Any

TEACHERS = ("planner", "guarded_planner", "search", "lookahead", "dispatcher")

#: The planner's options a training config may set (``pretrain.planner_<option>``).
PLANNER_OPTIONS = ("expect_failures", "rescue")


def make_teacher(name: str, planner_horizon: int, planner_margin: float, seed: int,
                 learner: dict[str, Any] | None = None, rule_weight: float = 0.0,
                 **planner_options: Any):
    """The teacher ``name`` (a name from before 0.2.0 is read as its new name, with a note);
    ``planner_options`` (of :data:`PLANNER_OPTIONS`) go to the planner of ``planner`` and
    ``guarded_planner``; ``learner`` (checkpoint content, the actor being fit) is the proposer
    of ``lookahead`` (``None``: the dispatcher), with the dispatcher as its prior at
    ``rule_weight`` > 0 (:mod:`agents.controllers.prior`)."""
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
    if name == "lookahead":
        return LookaheadTeacher(learner, seed, rule_weight)
    if name == "search":
        from agents.controllers.guard import GuardController
        from agents.controllers.lookahead_settings import LookaheadSettings

        return GuardController(proposer=DispatcherController(),
                               rollout_policy=DispatcherController(),
                               settings=LookaheadSettings(quiet_pct=101.0, candidates=99,
                                                          seed=seed))
    if name not in TEACHERS:
        raise ValueError(f"teacher {name!r}: use one of {TEACHERS}")
    planner = PlannerController(horizon=planner_horizon, margin=planner_margin, seed=seed,
                                **planner_options)
    if name == "guarded_planner":
        from agents.controllers.guard import GuardController

        return GuardController(proposer=planner, rollout_policy=DispatcherController(), seed=seed)
    return planner


class LookaheadTeacher:
    """The look-ahead of the learned ATC around ``learner`` (checkpoint content; ``None``: the
    dispatcher proposes), labelling each decision with what the look-ahead takes.

    What a wrong choice costs (:func:`agents.training.imitation.label_weights`): where the
    look-ahead rolled out both the learner's choice and the dispatcher's (its reward contest,
    the same draws for both), their values, reward less
    :data:`~agents.controllers.search.LOSS_COST` per vehicle lost, are :attr:`last_q`; where it
    left the learner's choice for safety (that choice lost a vehicle or brought a charge under
    the margin, or the vehicle is below ``defer_pct``), the decision is :attr:`last_forced` and
    weighs the most. Elsewhere the learner's choice stands and is its label, at weight 1. With
    ``rule_weight`` > 0 the learner proposes with the dispatcher as its prior
    (:class:`~agents.controllers.prior.RulePriorController`)."""

    def __init__(self, learner: dict[str, Any] | None, seed: int, rule_weight: float = 0.0) -> None:
        from agents.controllers.dispatcher import DispatcherController
        from agents.controllers.gcn import GCNController
        from agents.controllers.lookahead import LookaheadController
        from agents.controllers.prior import RulePriorController

        proposer = DispatcherController() if learner is None else GCNController(learner)
        if learner is not None and rule_weight > 0:
            proposer = RulePriorController(proposer, DispatcherController(), rule_weight)
        #: The look-ahead that decides.
        self.look = LookaheadController(proposer=proposer, rollout_policy=DispatcherController(),
                                        seed=seed)
        self.last_q: dict[int, float] = {}
        self.last_forced = False

    def bind(self, sim: Any) -> None:
        self.look.bind(sim)

    def reset(self, seed: int | None = None) -> None:
        self.look.reset(seed=seed)

    def close(self) -> None:
        self.look.close()

    def act(self, observation: dict) -> int:
        from agents.controllers.search import LOSS_COST

        look = self.look
        proposal = int(look.proposer.act(observation))
        label = int(look.act(observation))
        self.last_q = {a: v[1] - LOSS_COST * v[0] for a, v in look.last_contest.items()}
        self.last_forced = label != proposal and not self.last_q
        return label
