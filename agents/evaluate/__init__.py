"""Evaluate controllers: run episodes, summarise them with bootstrap confidence intervals,
and write tables, figures and a Markdown report (``python -m agents.evaluate --help``).

One job per module, each importing only those listed before it:

* ``metrics``: the metrics' labels, units and directions, the cases' display names;
* ``settings``: what to run (settings, suites, overrides) and what a run holds;
* ``episodes``: the execution layer (this process or a pool of worker processes);
* ``stats``: bootstrap intervals and the summary rows;
* ``unforced``: the unforced losses of a day, and their rows in the summary;
* ``paired``: two agents compared day by day (a command of its own; the package does not
  import it, so ``python -m agents.evaluate.paired`` runs it cleanly);
* ``run``: input checks, then running and summarising;
* ``tables``: the console table, CSV and JSON;
* ``figures``: the case-study and action-distribution charts;
* ``report``: the Markdown report and writing every file;
* ``cli``: the command line.
"""

from agents.evaluate.cli import main
from agents.evaluate.episodes import run_task
from agents.evaluate.report import write_outputs
from agents.evaluate.run import evaluate, evaluate_controller
from agents.evaluate.settings import (
    DEFAULT_AGENTS, DEFAULT_CONFIGS, SUITE_DIR, EpisodeRecord, EpisodeTask, EvalSettings,
    Evaluation, InputError, load_suite, parse_overrides,
)
from agents.evaluate.stats import bootstrap_ci, describe, summarize
from agents.evaluate.tables import format_table

__all__ = [
    "DEFAULT_AGENTS", "DEFAULT_CONFIGS", "SUITE_DIR", "EpisodeRecord", "EpisodeTask",
    "EvalSettings", "Evaluation", "InputError", "bootstrap_ci", "describe", "evaluate",
    "evaluate_controller",
    "format_table", "load_suite", "main", "parse_overrides", "run_task", "summarize",
    "write_outputs",
]
