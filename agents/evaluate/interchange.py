"""An evaluation in the community's formats: ``marl_eval.json``, the raw-data layout of
MARL-eval (InstaDeep's ``id-marl-eval``, the standardised protocol of Gorsane et al. 2022),
whose score matrices rliable (Agarwal et al. 2021) aggregates.

The layout nests environment, task, algorithm and run::

    {"marl_vertiport": {                     # the environment
       "paper_uncertain": {                  # a task: one case (env config) of the evaluation
         "dispatcher": {                     # an algorithm: one agent spec
           "seed_1000000": {                 # a run: one day (its seed), an independent trial
             "step_0": {"step_count": 1440, "total_reward": [2431.5], ...},
             "absolute_metrics": {"total_reward": [2431.5], ...}}}}}}

A controller evaluated here has no training steps, so each run has one logging step, its day,
and the same values as its absolute metrics; every metric is a list of one value (the day's).
Every agent of an evaluation plays the same days, as rliable's matrices need. A metric that is
undefined on some day of a case (NaN: a separation with a fleet of one) is left out of that
case, since the format has no missing values.
"""

from __future__ import annotations

import json
import math
from typing import Any

from agents.evaluate.settings import Evaluation

__all__ = ["ENVIRONMENT", "marl_eval_data", "marl_eval_json"]

#: The environment's name in the layout.
ENVIRONMENT = "marl_vertiport"


def marl_eval_data(evaluation: Evaluation) -> dict[str, Any]:
    """The evaluation's completed days in MARL-eval's raw-data layout (module docstring)."""
    tasks: dict[str, Any] = {}
    for config in evaluation.settings.configs:
        records = [r for r in evaluation.records if r.task.config == config and r.metrics]
        metrics = [m for m in evaluation.metrics if m != "steps" and all(
            math.isfinite(float(r.metrics[m])) for r in records)]
        algorithms: dict[str, Any] = {}
        for r in records:
            values = {m: [float(r.metrics[m])] for m in metrics}
            algorithms.setdefault(r.task.agent, {})[f"seed_{r.task.seed}"] = {
                "step_0": {"step_count": int(r.metrics.get("steps", 0)), **values},
                "absolute_metrics": values}
        if algorithms:
            tasks[config] = algorithms
    return {ENVIRONMENT: tasks}


def marl_eval_json(evaluation: Evaluation) -> str:
    """:func:`marl_eval_data` as JSON text (no NaN: strict JSON)."""
    return json.dumps(marl_eval_data(evaluation), allow_nan=False) + "\n"
