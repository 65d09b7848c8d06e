"""The learned policy with a rule as its prior: the policy departs from the rule only where it
is sure.

At each decision :class:`RulePriorController` takes the legal action ``a`` with the highest

    log pi(a) + weight * [a is the rule's choice]

where ``pi`` is the policy's action distribution (the GCN's by default) and the rule is the
dispatcher by default. So the rule's choice stands unless the policy holds another action
``e ** weight`` times likelier than it (``weight=3``: 20 times); ``weight=0`` is the policy
alone, a large weight the rule alone. Both parts act from the observation only (the
dispatcher, bound to an env, adopts its constant drains and reserve, not its state), so the
controller needs no simulator: about a quarter of a millisecond a decision, the GCN's pass and
the dispatcher's rules.

Why: the policy alone trails the dispatcher mostly by the vehicles it loses; where it is sure
it is mostly right, and where it hesitates the rule is the better guess. On 600 test days the
shipped policy with its prior is −74 a day of the dispatcher against the policy's −611 alone,
and a policy fit with the prior (``pretrain.rule_weight``) is +36 (experiments/rule-prior).

Specs: ``prior`` (the shipped checkpoint and the dispatcher), ``prior[weight=3]``,
``prior[policy=runs/x/model_fit2.pt]``, ``prior[policy=gcn,rule=fcfs]`` (another rule as the
prior), ``lookahead[proposer=prior]`` (as the look-ahead's proposer).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from agents.controllers.base import Controller

__all__ = ["DEFAULT_WEIGHT", "RulePriorController", "trained_weight"]

#: The prior's weight in nats (log-probability) as shipped; chosen on validation days
#: (experiments/rule-prior).
DEFAULT_WEIGHT = 3.0


def trained_weight(policy: Any) -> float:
    """The prior's weight ``policy`` was fit with (``pretrain.rule_weight`` of its checkpoint's
    train config; 0: fit alone, or not a checkpoint)."""
    info = getattr(policy, "train_info", None) or {}
    pretrain = (info.get("train_config") or {}).get("pretrain") or {}
    return float(pretrain.get("rule_weight", 0.0) or 0.0)


def _build(part: Any, role: str) -> Any:
    """``part`` as a controller: a spec string is built, an object is used as it is."""
    if isinstance(part, str):
        from agents.controllers.registry import make_controller

        return make_controller(part)
    if not callable(getattr(part, "act", None)):
        raise ValueError(f"prior: the {role} {part!r} has no act(observation) method")
    return part


class RulePriorController(Controller):
    """``policy`` (a spec or an object with ``action_probabilities(observation) -> (A,)``)
    with ``rule`` (a spec or a controller) as its prior, the rule's choice weighing
    ``weight`` nats (module docstring); ``None``: the weight the policy's checkpoint was fit
    with (``pretrain.rule_weight``), else :data:`DEFAULT_WEIGHT`.

    Raises:
        ValueError: a negative or non-finite weight, or a policy without action
            probabilities (a rule, or a policy of another library that gives none).
    """

    name = "prior"

    def __init__(self, policy: Any = "gcn", rule: Any = "dispatcher",
                 weight: float | None = None) -> None:
        self.policy = _build(policy, "policy")
        if not callable(getattr(self.policy, "action_probabilities", None)):
            raise ValueError(f"prior: the policy {policy!r} gives no action probabilities "
                             "(a checkpoint or an ensemble does); it cannot be weighed against "
                             "a rule")
        if weight is None:
            weight = trained_weight(self.policy) or DEFAULT_WEIGHT
        if isinstance(weight, bool) or not isinstance(weight, (int, float)):
            raise ValueError(f"prior: weight must be a number of nats >= 0, got {weight!r}")
        weight = float(weight)
        if not math.isfinite(weight) or weight < 0:
            raise ValueError(f"prior: weight must be a finite number of nats >= 0, got {weight}")
        self.rule = _build(rule, "rule")
        self.weight = weight
        self.pure_act = bool(getattr(self.policy, "pure_act", False)
                             and getattr(self.rule, "pure_act", False))
        #: Decisions with a choice, and those where the policy's choice was not the rule's.
        self.decisions = self.departures = 0
        #: The rule's choice at the last decision.
        self.last_rule = -1

    def reset(self, seed: int | None = None) -> None:
        for part in (self.policy, self.rule):
            if hasattr(part, "reset"):
                part.reset(seed=seed)
        self.decisions = self.departures = 0

    def bind(self, sim: Any) -> None:
        for part in (self.policy, self.rule):
            if hasattr(part, "bind"):
                part.bind(sim)

    def close(self) -> None:
        for part in (self.policy, self.rule):
            if hasattr(part, "close"):
                part.close()

    def scores(self, observation: dict) -> np.ndarray:
        """``log pi(a) + weight * [a is the rule's choice]`` for every action ``(A,)``;
        ``-inf`` on illegal ones. The rule's choice is kept as :attr:`last_rule`."""
        mask = np.asarray(observation["action_mask"]).astype(bool)
        probs = np.asarray(self.policy.action_probabilities(observation), dtype=np.float64)
        with np.errstate(divide="ignore"):
            scores = np.where(mask & (probs > 0), np.log(probs), -np.inf)
        # A legal action the policy gives no probability at all (underflow) stays choosable.
        scores[mask & (probs <= 0)] = -1e9
        self.last_rule = int(self.rule.act(observation))
        if 0 <= self.last_rule < len(mask) and mask[self.last_rule]:
            scores[self.last_rule] += self.weight
        return scores

    def action_probabilities(self, observation: dict) -> np.ndarray:
        """The prior-weighted distribution ``(A,)``: the softmax of :meth:`scores` over the
        legal actions (a look-ahead's candidates, the decision log's alternatives)."""
        scores = self.scores(observation)
        legal = np.isfinite(scores)
        out = np.zeros(scores.shape)
        z = np.exp(scores[legal] - scores[legal].max())
        out[legal] = z / z.sum()
        return out

    def act(self, observation: dict) -> int:
        mask = np.asarray(observation["action_mask"])
        legal = int(mask.sum())
        if self.pure_act and legal == 1:
            return int(np.flatnonzero(mask)[0])
        best = int(np.argmax(self.scores(observation)))
        if legal > 1:
            self.decisions += 1
            self.departures += int(best != self.last_rule)
        return best
