"""``marl-vertiport``: one command for everything a user runs, once the package is installed.

Commands (``marl-vertiport COMMAND --help`` for each one's options):

    evaluate      evaluate controllers on cases or a suite (tables, CIs, figures, report)
    sweep         a grid of agents x cases x config overrides x days: tidy CSV and figure
    train         train the GCN ATC from a train config (warm start, PPO, evaluation)
    check-train   train as make train does, then compare with the shipped checkpoint: verdict
    check-results the shipped results name the shipped checkpoint and replay exactly
    curves        learning curves over training seeds, with intervals and baselines
    render        an animated GIF or MP4 of one episode of a controller, with its decisions
    worst-day     each controller's worst day of an evaluation, rendered with its decision log
    timeline      one day at a glance: batteries, statuses, delays, chargers, losses, failures
    bench         the speed and memory benchmark (docs/performance.md)
    capacity      whether each vertiport carries its fleet, from its config alone
    charger-study where the charging ports' minutes go on simulated days, vehicles lost
    paper-claims  the paper's case-study claims beside this project's measurements
    soak          many days with every uncertainty high: invariants after every step, memory
    demo          random legal actions for a few episodes, with steps per second
    info          spaces, feature columns and action names of an env config
    check-config  validate an env config and print it resolved

Each command is also a module (``python -m agents.evaluate`` and so on); this entry point only
dispatches to them, importing the one it runs. A name that changed in 0.2.0 (``heuristic``,
``rollout``, ``handback``, ...) still works and prints one line, ``note: ...``. Every error is
one line, ``error: ...``; ``--debug`` anywhere on the line shows the traceback instead.
``--trust`` anywhere on the line lets policy files of other libraries that only load by
unpickling be unpickled (which runs the code in them; under ``python -m``, set
``MARL_VERTIPORT_TRUST_FILES=1`` instead); without it they are refused, named.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from agents.common.names import show_notes_on_one_line
from agents.common.specs import TRUST_VARIABLE

#: Command -> (module whose ``main(argv)`` runs it, one-line help).
COMMANDS = {
    "evaluate": ("agents.evaluate.cli", "evaluate controllers on cases or a suite"),
    "sweep": ("agents.sweep.cli", "a grid of agents x cases x config overrides x days"),
    "train": ("agents.training.cli", "train the GCN ATC from a train config"),
    "curves": ("agents.curves.cli", "learning curves over training seeds"),
    "render": ("agents.render.cli", "an animated GIF or MP4 of one episode"),
    "worst-day": ("agents.render.worst_day", "each controller's worst day of an evaluation, rendered"),
    "timeline": ("agents.render.timeline", "one day at a glance, as a figure"),
    "bench": ("agents.bench.cli", "the speed and memory benchmark"),
    "check-train": ("agents.checks.train", "a fresh training run against the shipped checkpoint"),
    "check-results": ("agents.checks.results", "shipped results: their record and their first days replayed"),
    "capacity": ("agents.studies.capacity", "whether a vertiport carries its fleet, from its config"),
    "charger-study": ("agents.studies.charger_study", "where the charging ports' minutes go, simulated"),
    "paper-claims": ("agents.studies.paper_claims", "the paper's case-study claims, measured here"),
    "soak": ("agents.studies.soak", "many days with high uncertainty: invariants and memory"),
    "demo": ("marl_vertiport.cli", "random legal actions for a few episodes"),
    "info": ("marl_vertiport.cli", "spaces, features and action names of a config"),
    "check-config": ("marl_vertiport.cli", "validate an env config and print it resolved"),
}
#: The console command.
PROG = "marl-vertiport"
#: Commands that belong to ``marl_vertiport.cli``, whose ``main`` takes the command name too.
_ENV_COMMANDS = ("demo", "info", "check-config")


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser (for ``--help`` and errors); a command's own options are parsed by
    its module."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (_, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``argv`` (default: ``sys.argv[1:]``) to the command's module; its exit code.

    An error the command does not handle itself is printed as one line, ``error: ...``, and
    exits with status 1; ``--debug`` (anywhere in ``argv``) lets it raise, with its traceback.
    ``--trust`` (anywhere) sets :data:`agents.common.specs.TRUST_VARIABLE` for the command and
    the worker processes it starts."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    if "--trust" in argv:
        os.environ[TRUST_VARIABLE] = "1"
    argv = [a for a in argv if a not in ("--debug", "--trust")]
    if not argv or argv[0] not in COMMANDS:
        build_parser().parse_args(argv[:1])  # prints the help, or the error, and exits
    show_notes_on_one_line()
    command, rest = argv[0], argv[1:]
    module_name, _ = COMMANDS[command]
    # --help and the result files name the command as the user typed it.
    prog = f"{PROG} {command}"
    if command in _ENV_COMMANDS:  # one parser with the three as subcommands
        rest, prog = [command, *rest], PROG
    try:
        code = importlib.import_module(module_name).main(rest, prog=prog)
    except Exception as exc:  # one line for the user; the traceback with --debug
        if debug:
            raise
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"error: {message} ({type(exc).__name__}; --debug shows where)", file=sys.stderr)
        return 1
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
