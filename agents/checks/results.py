"""Are the shipped results still what the code and the shipped checkpoint give?
``marl-vertiport check-results`` (``make check-results``).

Every result set under ``docs/`` (an evaluation's ``results.json`` beside its
``episodes.csv``, a sweep's ``sweep.json`` beside its ``sweep.csv``) is checked twice:

1. **Its record** (``provenance``, agents/common/provenance.py): every agent that plays a
   checkpoint names the shipped one, by SHA-256, and the code it was made with is a commit
   without uncommitted changes.
2. **Its days, replayed**: the first ``--days`` days (default 2) of every agent x case (x sweep
   point) row group of the CSV are played again, through the same episode runner as the
   evaluation, on the code as it is; every column must come out exactly as written. Behaviour
   can change without the checkpoint changing (a fix in the simulator, a controller, the
   reward); this is what catches it. A change that moves the numbers on purpose regenerates
   the files (``make results``, ``make sweep``) in the same commit.

Exit codes: 0 every set holds, 1 a record or a replayed day differs (each one listed), 2 bad
input (a folder without result sets, a file that is not one).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from agents.common.names import canonical_spec
from agents.common.provenance import REPO_ROOT, file_sha256
from agents.common.specs import checkpoint_files

PROG = "python -m agents.checks.results"
#: Where the shipped result sets live.
DOCS = REPO_ROOT / "docs"
#: Days replayed per row group unless told otherwise.
DAYS = 2
#: The CSV's leading columns that name an episode rather than measure it.
KEY_COLUMNS = ("agent", "config", "episode", "seed")


class ResultsError(ValueError):
    """A result set that cannot be read; nothing was replayed."""


@dataclass
class ResultSet:
    """One shipped result set: its JSON record, its per-episode CSV and what each row ran."""

    record_path: Path
    csv_path: Path
    agents: list[str]
    overrides: dict[str, Any]
    """Overrides of every episode (an evaluation's ``--set``, a sweep's ``set``)."""
    grid: dict[str, list[Any]] = field(default_factory=dict)
    """A sweep's swept keys and their values (columns of its CSV)."""
    provenance: dict[str, Any] | None = None

    @property
    def name(self) -> str:
        try:
            return self.record_path.parent.relative_to(REPO_ROOT).as_posix()
        except ValueError:
            return str(self.record_path.parent)


def find_sets(root: Path = DOCS) -> list[ResultSet]:
    """Every result set below ``root``, in path order."""
    sets = []
    for path in sorted([*root.rglob("results.json"), *root.rglob("sweep.json")]):
        sets.append(read_set(path))
    return sets


def read_set(path: Path) -> ResultSet:
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ResultsError(f"{path}: not a readable result record ({exc})") from None
    if not isinstance(doc, dict):
        raise ResultsError(f"{path}: not a result record (expected a JSON object)")
    if path.name == "results.json":
        settings = doc.get("settings") or {}
        return ResultSet(path, path.with_name("episodes.csv"), list(settings.get("agents", [])),
                         dict(settings.get("overrides") or {}), provenance=doc.get("provenance"))
    spec = doc.get("spec") or {}
    return ResultSet(path, path.with_name("sweep.csv"), list(spec.get("agents", [])),
                     dict(spec.get("set") or {}), dict(spec.get("grid") or {}),
                     provenance=doc.get("provenance"))


# ------------------------------------------------------------------------------ the record
def record_problems(result: ResultSet, shipped: Path) -> list[str]:
    """What the set's record says that it should not: no record, a checkpoint that is not the
    shipped one (or none named for an agent that plays one), code with uncommitted changes or
    no commit at all."""
    record = result.provenance
    if not record:
        return ["no provenance record: made before results recorded it; regenerate the set"]
    problems = []
    code = record.get("code") or {}
    if not code.get("commit"):
        problems.append("the record names no code commit")
    if code.get("dirty") is not False:
        problems.append(f"made with uncommitted changes to the code (commit {code.get('commit')})")
    shipped_sha = file_sha256(shipped)
    named = record.get("checkpoints") or {}
    for agent in result.agents:
        if not checkpoint_files(agent):
            continue
        entries = named.get(agent)
        if entries is None:
            problems.append(f"agent {agent!r} plays a checkpoint the record does not name")
            continue
        for entry in entries if isinstance(entries, list) else [entries]:
            if entry.get("sha256") != shipped_sha:
                problems.append(f"agent {agent!r} played {entry.get('path')} (sha256 "
                                f"{str(entry.get('sha256'))[:16]}), not the shipped checkpoint "
                                f"(sha256 {shipped_sha[:16]})")
    return problems


# ------------------------------------------------------------------------------ the replay
def read_rows(result: ResultSet) -> tuple[list[str], list[dict[str, str]]]:
    try:
        with result.csv_path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            rows = list(reader)
            header = list(reader.fieldnames or [])
    except (OSError, UnicodeDecodeError) as exc:
        raise ResultsError(f"{result.csv_path}: cannot be read ({exc})") from None
    missing = [c for c in (*KEY_COLUMNS, *result.grid) if c not in header]
    if missing:
        raise ResultsError(f"{result.csv_path}: no column {', '.join(missing)}")
    return header, rows


def first_days(result: ResultSet, rows: list[dict[str, str]], days: int) -> list[dict[str, str]]:
    """The first ``days`` rows (by episode) of every agent x case x point group, in file order."""
    groups: dict[tuple[str, ...], list[dict[str, str]]] = {}
    for row in rows:
        key = (row["agent"], row["config"], *(row[k] for k in result.grid))
        groups.setdefault(key, []).append(row)
    out = []
    for group in groups.values():
        out += sorted(group, key=lambda r: int(r["episode"]))[:days]
    return out


def _grid_value(result: ResultSet, key: str, cell: str) -> Any:
    """The swept value a CSV cell stands for (the grid's own value, with its type)."""
    for value in result.grid[key]:
        if str(value) == cell:
            return value
    raise ResultsError(f"{result.csv_path}: {key}={cell!r} is not a value of the sweep's grid")


def tasks_of(result: ResultSet, rows: list[dict[str, str]]) -> list:
    from agents.evaluate.settings import EpisodeTask

    tasks = []
    # The env's rules the set was made under (sets from before the record named them: v0).
    rules = int((result.provenance.get("env") or {}).get("rules", 0))
    for row in rows:
        point = {k: _grid_value(result, k, row[k]) for k in result.grid}
        overrides = tuple({**result.overrides, **point}.items())
        # Rows made before 0.2.0 name controllers by their old names: the same controllers.
        tasks.append(EpisodeTask(canonical_spec(row["agent"], note=False), row["config"],
                                 int(row["episode"]), int(row["seed"]), overrides, rules))
    return tasks


def as_written(header: list[str], result: ResultSet, row: dict[str, str],
               metrics: dict[str, Any]) -> dict[str, str]:
    """A replayed episode's row as the evaluation writes it (floats to ``CSV_DIGITS``
    significant digits, every value through ``csv``)."""
    from agents.evaluate.tables import csv_metric

    values = [row[c] if c in (*KEY_COLUMNS, *result.grid) else csv_metric(metrics.get(c, "<missing>"))
              for c in header]
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(values)
    return dict(zip(header, next(csv.reader(io.StringIO(buf.getvalue())))))


def replay(sets: Sequence[ResultSet], days: int, backend, progress: bool = True
           ) -> dict[str, list[str]]:
    """Replay the first ``days`` days of every group of every set; per set, the differences
    (``agent / case / seed: column: shipped X, now Y``), empty where every column matches."""
    from agents.evaluate.episodes import close_envs, run_tasks

    plan = []
    for result in sets:
        header, rows = read_rows(result)
        chosen = first_days(result, rows, days)
        plan.append((result, header, chosen, tasks_of(result, chosen)))
    tasks = [t for *_, ts in plan for t in ts]
    try:
        records, error = run_tasks(tasks, backend, progress)
    finally:
        close_envs()
    if error is not None:
        raise RuntimeError(f"the replay stopped: {error}")
    by_task = {id(t): r for t, r in zip(tasks, records)}
    out: dict[str, list[str]] = {}
    for result, header, chosen, result_tasks in plan:
        problems = []
        for row, task in zip(chosen, result_tasks):
            now = as_written(header, result, row, by_task[id(task)].metrics)
            where = f"{row['agent']} / {row['config']}" + "".join(
                f" / {k}={row[k]}" for k in result.grid) + f" / seed {row['seed']}"
            for column in header:
                if now[column] != row[column]:
                    problems.append(f"{where}: {column}: shipped {row[column]}, now {now[column]}")
        out[result.name] = problems
    return out


# ------------------------------------------------------------------------------ command
def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    import os

    from agents.controllers.registry import SHIPPED_CHECKPOINT
    from agents.execution import BackendError, add_backend_arguments, backend_from_args

    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="*", type=Path, default=[DOCS], metavar="FOLDER",
                        help="where to look for result sets (default: docs/)")
    parser.add_argument("--days", type=int, default=DAYS, metavar="N",
                        help=f"days replayed per agent x case x point (default {DAYS}; 0: "
                             "check the records only)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, metavar="N",
                        help="local worker processes (default: every core)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    try:
        if args.days < 0:
            raise ResultsError(f"--days must be >= 0, got {args.days}")
        sets = [s for folder in args.folders for s in find_sets(folder)]
        if not sets:
            raise ResultsError(f"no result set (results.json or sweep.json) in "
                               f"{', '.join(map(str, args.folders))}")
        backend = backend_from_args(args, args.workers) if args.days else None
    except (ResultsError, BackendError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    failed = 0
    records = {s.name: record_problems(s, SHIPPED_CHECKPOINT) for s in sets}
    replays: dict[str, list[str]] = {}
    if backend is not None:
        with backend:
            try:
                replays = replay(sets, args.days, backend, not args.no_progress)
            except ResultsError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 2
            except RuntimeError as exc:  # an episode failed: the code no longer runs it
                print(f"error: {exc}", file=sys.stderr)
                return 1
    for s in sets:
        problems = records[s.name] + replays.get(s.name, [])
        failed += bool(problems)
        state = "ok" if not problems else f"{len(problems)} problem(s)"
        what = "record" + (f" and the first {args.days} days of every row group replayed"
                           if args.days else " only")
        print(f"{s.name}: {state} ({what})")
        for p in problems[:20]:
            print(f"  {p}")
        if len(problems) > 20:
            print(f"  ... and {len(problems) - 20} more")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
