"""Sweep a grid of agents x cases x config overrides x evaluation days, on this machine or a
Ray cluster, into one tidy CSV and a figure of each metric against the swept value.

Usage::

    python -m agents.sweep wind                          # configs/sweeps/wind.yaml
    python -m agents.sweep wind --episodes 5 --out runs/sweeps/wind_quick
    python -m agents.sweep configs/sweeps/wind.yaml --backend ray --ray-address auto
    python -m agents.sweep wind --grid uncertainty.wind_gust_prob=0,0.3 --set schedule.episode_steps=720

Outputs in ``--out`` (default ``runs/sweeps/<name>``): ``sweep.csv`` (one row per episode:
agent, config, the swept keys, episode, seed, every metric), ``summary.csv`` (mean, std and
95 % bootstrap CI per agent, case, point and metric), ``sweep.png`` and ``sweep.json`` (the
sweep as run, where it ran, whether it completed). Exit codes as ``agents.evaluate``: 0 done,
1 a controller or the simulation failed mid-run (completed episodes written, marked
incomplete), 2 bad input (nothing is run), 130 Ctrl-C (as for 1).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import yaml

from agents.common.provenance import provenance
from agents.controllers.registry import agent_help
from agents.evaluate.cli import check_outputs
from agents.evaluate.episodes import close_envs, run_tasks
from agents.evaluate.run import check_agent
from agents.evaluate.settings import INTERRUPTED, InputError, parse_overrides
from agents.evaluate.tables import format_interval
from agents.execution import Backend, BackendError, add_backend_arguments, backend_from_args
from agents.sweep.outputs import SweepResult, summary_rows, write_outputs
from agents.sweep.spec import SweepSpec, load_sweep, point_label


PROG = "python -m agents.sweep"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweep", metavar="SWEEP",
                        help="a sweep file: a name in configs/sweeps/ or a YAML path")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="output folder (default: runs/sweeps/<name>)")
    parser.add_argument("--agents", nargs="+", default=None, metavar="AGENT",
                        help=f"replace the file's agents, each {agent_help()}")
    parser.add_argument("--configs", nargs="+", default=None, metavar="CONFIG",
                        help="replace the file's cases (env config names or YAML paths)")
    parser.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...",
                        help="sweep KEY over these values (each parsed as YAML), added to or "
                             "replacing the file's grid; repeatable")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="a fixed override of every point; repeatable")
    parser.add_argument("--episodes", type=int, default=None, metavar="N",
                        help="days per point: the first N evaluation seeds")
    parser.add_argument("--seeds", default=None, metavar="START:STOP",
                        help="days per point: these seeds (validation or test seeds)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, metavar="N",
                        help="local backend: worker processes, 1 runs in this process; ray "
                             "backend: the CPUs of the Ray instance it starts when it joins no "
                             "cluster (default: the number of CPU cores, %(default)s)")
    add_backend_arguments(parser)
    parser.add_argument("--no-progress", action="store_true",
                        help="do not show the progress bar on stderr")
    return parser


def parse_grid_option(item: str) -> tuple[str, list[Any]]:
    """``KEY=V1,V2`` -> ``(KEY, [V1, V2])``, each value parsed as YAML."""
    key, sep, raw = item.partition("=")
    if not sep or not key.strip() or not raw.strip():
        raise InputError(f"--grid {item!r}: expected KEY=V1,V2,..., e.g. "
                         f"uncertainty.wind_gust_prob=0,0.1,0.2")
    try:
        values = [yaml.safe_load(v) for v in raw.split(",")]
    except yaml.YAMLError as exc:
        raise InputError(f"--grid {item!r}: a value is not valid YAML ({exc})") from None
    return key.strip(), values


def changes_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The command line's changes to the sweep file (see :func:`load_sweep`)."""
    changes: dict[str, Any] = {}
    if args.agents:
        changes["agents"] = args.agents
    if args.configs:
        changes["configs"] = args.configs
    if args.grid:
        changes["grid"] = dict(parse_grid_option(item) for item in args.grid)
    if args.overrides:
        changes["set"] = dict(parse_overrides(args.overrides))
    if args.episodes is not None:
        changes["episodes"] = args.episodes
    if args.seeds is not None:
        changes["seeds"] = args.seeds
    return changes


def validate(spec: SweepSpec) -> None:
    """Every agent builds and every case loads at every point, before anything runs.

    Raises:
        InputError: naming the agent, or the case and the point.
    """
    from marl_vertiport.config import ConfigError, load_config

    for agent in spec.agents:
        check_agent(agent)
    for config in spec.configs:
        for point in spec.points():
            try:
                load_config(config, **dict(spec.fixed + point))
            except (ConfigError, OSError) as exc:
                raise InputError(f"config {config!r} at {point_label(point) or 'the point'}: "
                                 f"{exc}") from None


def run_sweep(spec: SweepSpec, backend: Backend, progress: bool = True) -> SweepResult:
    """Run every episode of ``spec`` on ``backend``; the records come back in task order."""
    made_with = provenance(spec.agents)  # the code and checkpoints as they are now
    start = time.perf_counter()
    given = dict.fromkeys(spec.keys)

    def label(task) -> str:
        values = {k: v for k, v in task.overrides if k in given}
        return f"{task.agent} / {task.config} / " + point_label(tuple(values.items()))

    try:
        records, error = run_tasks(spec.tasks(), backend, progress, label)
    finally:
        close_envs()
    return SweepResult(spec, records, error, time.perf_counter() - start, backend.describe(),
                       provenance=made_with)


def format_summary(result: SweepResult) -> str:
    """A console table: per agent, case and point, the reward and the safety metrics."""
    columns = [m for m in ("total_reward", "stranded", "collisions", "separation_losses",
                           "min_separation_m", "contacts")
               if m in result.metrics]
    rows = summary_rows(result)
    spec = result.spec
    lines = []
    header = ["agent", "config", *spec.keys, *columns]
    table = []
    seen: dict[tuple[Any, ...], dict[str, str]] = {}
    for row in rows:
        key = (row["agent"], row["config"], *(row[k] for k in spec.keys))
        if row["metric"] in columns:
            seen.setdefault(key, {})[row["metric"]] = format_interval(row)
    for key, cells in seen.items():
        table.append([str(k) for k in key] + [cells.get(m, "") for m in columns])
    widths = [max(len(h), *(len(r[i]) for r in table)) for i, h in enumerate(header)]
    lines.append("  ".join(h.ljust(w) for h, w in zip(header, widths)))
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in table]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    """Command line entry point (``prog``: the command as the user typed it); returns the
    exit code."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(prog).parse_args(args_list)
    command = shlex.join([*prog.split(), *args_list])
    try:
        spec = load_sweep(args.sweep, changes_from_args(args))
        out = args.out or Path("runs/sweeps") / spec.name
        if args.workers < 1:
            raise InputError(f"--workers must be >= 1, got {args.workers}")
        if args.ray_address and args.backend != "ray":
            raise InputError("--ray-address needs --backend ray")
        check_outputs(out, None)
        validate(spec)
        backend = backend_from_args(args, args.workers)
    except (InputError, BackendError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    with backend:
        tasks = len(spec.tasks())
        print(f"sweep {spec.name}: {len(spec.agents)} agents x {len(spec.configs)} cases x "
              f"{len(spec.points())} points x {spec.episodes} days = {tasks} episodes on "
              f"{backend.describe()}", file=sys.stderr)
        result = run_sweep(spec, backend, progress=not args.no_progress)
    if result.records:
        print(format_summary(result))
    written = write_outputs(result, out, command)
    print(f"\n{len(result.records)} episodes in {result.seconds:.1f} s; wrote "
          + ", ".join(str(p) for p in written), file=sys.stderr)
    if result.error is not None:
        print(f"error: {result.error}", file=sys.stderr)
        print(f"error: the sweep is incomplete: {len(result.records)} of {tasks} episodes were "
              f"completed and written to {out} (sweep.json has \"complete\": false); no figure "
              "was written", file=sys.stderr)
        return 130 if result.error == INTERRUPTED else 1
    return 0
