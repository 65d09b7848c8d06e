"""Evaluate controllers on the paper's two cases: per-episode metrics, confidence intervals,
the paper's case-study and action-distribution charts, and a Markdown report.

Every agent plays the same held-out days (``EVAL_SEEDS[:N]``) of every case through the AEC
API; an episode is fully determined by (agent, case, seed), so the numbers do not depend on how
many worker processes run them, nor on whether they run here or on a Ray cluster.

Usage::

    python -m agents.evaluate --agents random fcfs dispatcher --episodes 50 --out runs/eval
    python -m agents.evaluate --agents random --episodes 3 --set schedule.episode_steps=60
    python -m agents.evaluate --agents random fcfs dispatcher --out docs/results \\
        --report docs/results.md
    python -m agents.evaluate --agents fcfs dispatcher --episodes 1000 --backend ray \\
        --ray-address auto        # on the Ray cluster this machine belongs to (docs/scaling.md)

Outputs in ``--out``: ``episodes.csv``, ``summary.csv``, ``results.json``, ``case_study.png``,
``action_distribution.png`` (and the ``--report`` file). Exit codes: 0 done, 1 a controller or
the simulation failed mid-run (the episodes completed so far are written and ``results.json``
says the run is incomplete), 2 bad input (nothing is run), 130 interrupted with Ctrl-C (partial
results written as for 1).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path
from typing import Iterable, Sequence

from agents.common.seeds import parse_seed_range
from agents.controllers.registry import agent_help
from agents.evaluate.settings import (
    BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, DEFAULT_AGENTS, DEFAULT_CONFIGS, EvalSettings,
    Evaluation, INTERRUPTED, InputError, SuiteConfig, load_suite, parse_overrides,
)
from agents.evaluate.episodes import close_envs
from agents.evaluate.run import evaluate, validate
from agents.evaluate.tables import format_table
from agents.evaluate.report import write_outputs
from agents.execution import Backend, BackendError, add_backend_arguments, backend_from_args
from marl_vertiport.config import LATEST_RULES, RULES_VERSIONS

# ============================================================================ CLI


PROG = "python -m agents.evaluate"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--agents", nargs="+", default=None, metavar="AGENT",
                        help=f"controllers to evaluate, each {agent_help()} "
                             f"(default: {' '.join(DEFAULT_AGENTS)})")
    parser.add_argument("--configs", nargs="+", default=None, metavar="CONFIG",
                        help="cases: config names in configs/env/ or YAML paths "
                             f"(default: {' '.join(DEFAULT_CONFIGS)} = the paper's case 1 and case 2)")
    parser.add_argument("--episodes", type=int, default=None, metavar="N",
                        help="episodes (days) per agent and case, on seeds EVAL_SEEDS[:N] "
                             "(default: 50, the paper's protocol)")
    parser.add_argument("--suite", default=None, metavar="NAME",
                        help="an evaluation suite in configs/suites/ (or a YAML path): its "
                             "agents, cases and seeds, unless given here too; --episodes N "
                             "takes the first N of the suite's own seeds")
    parser.add_argument("--seeds", default=None, metavar="START:STOP",
                        help="evaluate on seeds START .. STOP-1 instead (validation seeds "
                             "800000-999999 for development, test seeds >= 1000000 for "
                             "reported numbers; training seeds are refused)")
    parser.add_argument("--rules", type=int, default=LATEST_RULES, choices=RULES_VERSIONS,
                        help=f"the env's rules version: vertiport_v{{N}} (default "
                             f"{LATEST_RULES}; 0: no separation check)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, metavar="N",
                        help="local backend: worker processes, 1 runs in this process; ray "
                             "backend: the CPUs of the Ray instance it starts when it joins no "
                             "cluster (default: the number of CPU cores, %(default)s)")
    add_backend_arguments(parser)
    parser.add_argument("--out", type=Path, default=Path("runs/eval"), metavar="DIR",
                        help="output folder, created if needed (default: %(default)s)")
    parser.add_argument("--report", type=Path, default=None, metavar="PATH",
                        help="also write a Markdown report there (e.g. docs/results.md)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="config override for every case, value parsed as YAML; repeatable "
                             "(e.g. --set schedule.episode_steps=60)")
    parser.add_argument("--bootstrap", type=int, default=BOOTSTRAP_RESAMPLES, metavar="N",
                        help="bootstrap resamples for the confidence intervals "
                             "(default: %(default)s)")
    parser.add_argument("--bootstrap-seed", type=int, default=BOOTSTRAP_SEED, metavar="SEED",
                        help="seed of the bootstrap's generator (default: %(default)s)")
    parser.add_argument("--no-progress", action="store_true",
                        help="do not show the progress bar on stderr")
    return parser


def _writable_folder(path: Path) -> str | None:
    """Why files could not be written into folder ``path`` (created where missing), or None.
    Creates nothing."""
    if path.exists():
        if not path.is_dir():
            return "exists and is not a folder"
        return None if os.access(path, os.W_OK | os.X_OK) else "the folder is not writable"
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"cannot be created: {ancestor} is not a folder"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"cannot be created: {ancestor} is not writable"
    return None


def check_outputs(out: Path, report: Path | None) -> None:
    """Fail before any episode runs when the results could not be written: ``out`` is a file
    or cannot be created, or ``report`` is a folder or cannot be written. Creates nothing."""
    problem = _writable_folder(out)
    if problem:
        raise InputError(f"--out {out}: {problem}")
    if report is not None:
        if report.is_dir():
            raise InputError(f"--report {report}: is a folder; give a file name such as report.md")
        problem = _writable_folder(report.parent)
        if problem:
            raise InputError(f"--report {report}: its folder {report.parent} {problem}")


def _unique(items: Iterable[str]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(items))


def suite_days(suite: SuiteConfig, episodes: int | None) -> tuple[str | None, int | None]:
    """``(--seeds, --episodes)`` of a suite run: its own seed range, cut to its first
    ``episodes`` seeds when a count is given, or, for a suite without a range, the count
    (``EVAL_SEEDS[:n]``). A count beyond the suite's range is an error: the suite's days are
    kept apart from other evaluations', so none are added from elsewhere."""
    if not suite.seeds:
        return None, suite.episodes if episodes is None else episodes
    try:
        days = parse_seed_range(suite.seeds)
    except ValueError as exc:
        raise InputError(f"suite {suite.name}: seeds: {exc}") from None
    if episodes is None:
        return suite.seeds, None
    if not 1 <= episodes <= len(days):
        raise InputError(f"--episodes {episodes}: suite {suite.name} has {len(days)} days "
                         f"(seeds {suite.seeds}); give 1 to {len(days)}")
    return f"{days.start}:{days.start + episodes}", None


def run_on(backend: Backend, settings: EvalSettings, names: dict[str, list[str]],
           progress: bool) -> Evaluation:
    """Run the evaluation on ``backend``, saying where on stderr first."""
    if progress:
        print(f"{len(settings.tasks())} episodes on {backend.describe()}", file=sys.stderr)
    return evaluate(settings, progress=progress, action_names=names, backend=backend)


def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    """Command line entry point (``prog``: the command as the user typed it, for ``--help``
    and the results' record); returns the exit code (0 ok, 1 failed mid-run, 2 bad input)."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(prog).parse_args(args_list)
    command = shlex.join([*prog.split(), *args_list])
    try:
        agents, configs = args.agents or list(DEFAULT_AGENTS), args.configs or list(DEFAULT_CONFIGS)
        if args.suite is not None:
            suite = load_suite(args.suite)
            agents, configs = args.agents or list(suite.agents), args.configs or list(suite.configs)
            if args.seeds is None:
                args.seeds, args.episodes = suite_days(suite, args.episodes)
        episodes, first_seed = 50 if args.episodes is None else args.episodes, None
        if args.seeds is not None:
            try:
                seeds = parse_seed_range(args.seeds)
            except ValueError as exc:
                raise InputError(f"--seeds: {exc}") from None
            if args.episodes is not None and args.episodes != len(seeds):
                raise InputError(f"--episodes {args.episodes} and --seeds {args.seeds} "
                                 f"({len(seeds)} seeds) disagree; give one of them")
            episodes, first_seed = len(seeds), seeds.start
        settings = EvalSettings(agents=_unique(agents), configs=_unique(configs),
                                episodes=episodes, first_seed=first_seed,
                                overrides=parse_overrides(args.overrides),
                                bootstrap=args.bootstrap, bootstrap_seed=args.bootstrap_seed,
                                rules=args.rules)
        if args.workers < 1:
            raise InputError(f"--workers must be >= 1, got {args.workers}")
        if args.ray_address and args.backend != "ray":
            raise InputError("--ray-address needs --backend ray")
        check_outputs(args.out, args.report)
        names = validate(settings)
        backend = backend_from_args(args, args.workers)
    except (InputError, BackendError) as exc:
        close_envs()
        print(f"error: {exc}", file=sys.stderr)
        return 2
    with backend:
        evaluation = run_on(backend, settings, names, not args.no_progress)
    table = format_table(evaluation)
    if table:
        print(table)
    written = write_outputs(evaluation, args.out, command, args.report)
    print(f"\n{len(evaluation.records)} episodes in {evaluation.seconds:.1f} s; wrote "
          + ", ".join(str(p) for p in written), file=sys.stderr)
    if evaluation.error is not None:
        print(f"error: {evaluation.error}", file=sys.stderr)
        print(f"error: the run is incomplete: {len(evaluation.records)} of "
              f"{len(settings.tasks())} episodes were completed and written to {args.out} "
              "(results.json has \"complete\": false); no figures or report were written",
              file=sys.stderr)
        return 130 if evaluation.error == INTERRUPTED else 1
    return 0

