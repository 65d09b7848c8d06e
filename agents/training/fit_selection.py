"""Which of the warm start's fits goes on to PPO (``pretrain.keep``).

DAgger returns the best of its iterates, not necessarily the last. Each fit is scored by the
days it drives: the full days of the round after its fit (``round``: days of its own, so two
fits' scores also differ by their days' difficulty), or the full days of the last round, which
every fit then drives (``paired``: the same days for all). ``last`` keeps the last fit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: The rules by which the warm start keeps one of its fits (``pretrain.keep``).
KEEP_RULES = ("round", "paired", "last")


def day_score(metrics: dict[str, Any], lost_vehicle_penalty: float) -> float:
    """What a fit is scored by on a day it drove: the paper's total reward minus
    ``lost_vehicle_penalty`` per vehicle lost (the training reward's lost-vehicle term)."""
    return float(metrics["total_reward"]) - lost_vehicle_penalty * float(metrics["stranded"])


def mean_day_score(metrics: list[dict[str, Any]], day_steps: int,
                   lost_vehicle_penalty: float) -> float:
    """The mean :func:`day_score` of the full days (``day_steps`` steps) among ``metrics``;
    NaN where there is none (such a fit is never kept)."""
    return float(np.mean([day_score(m, lost_vehicle_penalty) for m in metrics
                          if m["steps"] == day_steps] or [float("nan")]))


def kept_fit(rule: str, scores: list[float], paired: list[float] | None = None) -> int:
    """The index of the fit the warm start keeps under ``rule`` (``pretrain.keep``): the best
    of ``scores`` (each fit's mean on the days it drove in the next round, ``round``), of
    ``paired`` (every fit on the same days, ``paired``), or the last fit (``last``)."""
    if rule == "last":
        return len(scores) - 1
    if rule == "paired":
        if not paired or len(paired) != len(scores):
            raise ValueError("pretrain.keep: paired needs every fit's score on the same days")
        return int(np.nanargmax(paired))
    return int(np.nanargmax(scores))
