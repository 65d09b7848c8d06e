"""Paired comparison of agents on the days they both played, from evaluation files.

Two policies that differ a little can still play the same day very differently (one strands a
vehicle, the other does not), so per-agent intervals overlap even where one agent is better.
Comparing them day by day on the same days (same case, same seed) removes the day's own
difficulty from the comparison: the difference of each day's total reward, candidate minus
base, its mean and its 95 % percentile-bootstrap interval (:func:`agents.evaluate.stats.
bootstrap_ci`, resampling days)::

    python -m agents.evaluate --agents runs/x/model_warmstart.pt runs/x/model_219.pt \\
        --configs paper paper_uncertain small twin wide --episodes 40 --seeds 800010:800050 \\
        --out runs/eval_x
    python -m agents.evaluate.paired runs/eval_x/episodes.csv \\
        --pair runs/x/model_warmstart.pt runs/x/model_219.pt

Each ``--pair BASE CANDIDATE`` gives a row; with several pairs (one per training seed, say) a
last row pools all their days. Beside the reward each row gives what the reward can hide: the
vehicles lost in the air and on the ground and the unresolved conflicts (the paper's S = -5,
counted as collisions) a day, base → candidate, and per case the mean difference with its
95 % interval (the same bootstrap over that case's days).

*Unforced losses* say which of those losses a controller could have avoided: on each day, the
vehicles it lost beyond the fewest any agent of a reference set lost on that day
(``--reference``; by default the dispatcher, the look-ahead planner and the look-ahead guard,
those of them the files hold), averaged over the days a reference agent played. The table goes
to stdout (Markdown); ``--csv`` also writes it. Exit codes: 0 done, 2 bad input (a missing or
foreign file, an agent not in the files, no day in common).
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from agents.common.files import write_atomic
from agents.common.names import canonical_agents, canonical_spec
from agents.evaluate.stats import bootstrap_ci
from agents.evaluate.unforced import DEFAULT_REFERENCE, Day, unforced_losses

#: Columns of ``episodes.csv`` this comparison reads.
NEEDED = ("agent", "config", "seed", "total_reward", "stranded_air", "stranded_ground", "collisions")


class PairedInputError(ValueError):
    """An evaluation file or an agent that cannot be compared; the message names it."""


def read_episodes(paths: Sequence[str | Path]) -> dict[str, dict[Day, dict[str, float]]]:
    """Per agent, per day ``(case, seed)``, the metrics of its episode, from ``episodes.csv``
    files of ``python -m agents.evaluate``; agents labelled by their names before 0.2.0
    (``heuristic``, ``rollout``, ``handback``) under their names now. A day an agent played
    twice with different results (files that contradict each other) raises
    :class:`PairedInputError`."""
    out: dict[str, dict[Day, dict[str, float]]] = {}
    for path in paths:
        path = Path(path)
        try:
            with path.open(newline="") as f:
                reader = csv.DictReader(f)
                missing = [c for c in NEEDED if c not in (reader.fieldnames or ())]
                if missing:
                    raise PairedInputError(f"{path}: not an episodes.csv of agents.evaluate "
                                           f"(no column {', '.join(missing)})")
                for n, row in enumerate(reader, start=2):
                    try:
                        day = (row["config"], int(row["seed"]))
                        values = {c: float(row[c]) for c in NEEDED[3:]}
                    except (TypeError, ValueError):
                        raise PairedInputError(f"{path}, line {n}: a seed or metric is not a "
                                               f"number") from None
                    agent = canonical_spec(row["agent"], note=False)  # names before 0.2.0
                    known = out.setdefault(agent, {})
                    if day in known and known[day] != values:
                        raise PairedInputError(f"{path}, line {n}: {agent} on {day[0]}, "
                                               f"seed {day[1]}, differs from another file's row")
                    known[day] = values
        except OSError as exc:
            raise PairedInputError(f"{path}: cannot be read ({exc.strerror or exc})") from None
        except UnicodeDecodeError:
            raise PairedInputError(f"{path}: not a text file") from None
    return out


def compare(episodes: dict[str, dict[Day, dict[str, float]]],
            pairs: Sequence[tuple[str, str]],
            reference: Sequence[str] = ()) -> list[dict[str, Any]]:
    """One row per pair (and a pooled row ``"all"`` for several pairs): the days both agents
    played, each one's mean reward, the mean paired difference with its 95 % bootstrap CI,
    lost vehicles (air, ground) and unresolved conflicts a day of each, and the mean
    difference per case (``by_case``) and its interval (``by_case_ci``). With a ``reference``
    set of agents, also each side's unforced losses a day (:func:`unforced_losses`) over the
    days a reference agent played (``reference_days``; ``None`` where there is none)."""
    for agent in reference:
        if agent not in episodes:
            raise PairedInputError(f"reference agent {agent!r} is in none of the files (they "
                                   f"hold: {', '.join(sorted(episodes)) or 'no episodes'})")
    rows, pooled = [], []
    for base, cand in pairs:
        for agent in (base, cand):
            if agent not in episodes:
                raise PairedInputError(f"agent {agent!r} is in none of the files (they hold: "
                                       f"{', '.join(sorted(episodes)) or 'no episodes'})")
        days = sorted(set(episodes[base]) & set(episodes[cand]))
        if not days:
            raise PairedInputError(f"{base} and {cand} played no day in common")
        pooled += [(base, cand, d) for d in days]
        rows.append(_row(f"{base} → {cand}", [(base, cand, d) for d in days], episodes,
                         reference))
    if len(pairs) > 1:
        rows.append(_row("all", pooled, episodes, reference))
    return rows


def _row(label: str, played: list[tuple[str, str, Day]],
         episodes: dict[str, dict[Day, dict[str, float]]], reference: Sequence[str]
         ) -> dict[str, Any]:
    """A row of :func:`compare` over ``played``: ``(base agent, candidate agent, day)``."""
    days = [(episodes[b][d], episodes[c][d], d) for b, c, d in played]

    def mean(side: int, key: str) -> float:
        return float(np.mean([d[side][key] for d in days]))

    unforced: list[tuple[float, float]] = []
    for b, c, d in played:
        ub, uc = (unforced_losses(episodes, a, d, reference) for a in (b, c))
        if ub is not None and uc is not None:
            unforced.append((ub, uc))

    diff = np.array([c["total_reward"] - b["total_reward"] for b, c, _ in days])
    low, high = bootstrap_ci(diff)
    cases = sorted({day[0] for _, _, day in days})
    case_diff = {case: [c["total_reward"] - b["total_reward"] for b, c, day in days
                        if day[0] == case] for case in cases}
    by_case = {case: float(np.mean(d)) for case, d in case_diff.items()}
    by_case_ci = {case: bootstrap_ci(d) for case, d in case_diff.items()}
    return {"pair": label, "days": len(days), "base": mean(0, "total_reward"),
            "candidate": mean(1, "total_reward"), "difference": float(diff.mean()),
            "ci_low": low, "ci_high": high,
            **{f"{key}_{side}": mean(i, key) for i, side in enumerate(("base", "candidate"))
               for key in ("stranded_air", "stranded_ground", "collisions")},
            "reference_days": len(unforced),
            "unforced_base": float(np.mean([u[0] for u in unforced])) if unforced else None,
            "unforced_candidate": float(np.mean([u[1] for u in unforced])) if unforced else None,
            "by_case": by_case, "by_case_ci": by_case_ci}


def markdown(rows: list[dict[str, Any]], reference: Sequence[str] = ()) -> str:
    cases = sorted({c for r in rows for c in r["by_case"]})
    named = ", ".join(reference) or "none given"
    head = ["pair", "days", "base", "candidate", "paired difference [95 % CI]",
            "lost air / ground a day, base → candidate",
            f"unforced losses a day (reference: {named})", "unresolved conflicts (S = -5)",
            *(f"`{c}`" for c in cases)]
    lines = ["| " + " | ".join(head) + " |",
             "|---|" + "---:|" * 4 + "---|---|---|" + "---:|" * len(cases)]
    for r in rows:
        unforced = (f"{r['unforced_base']:.2f} → {r['unforced_candidate']:.2f} "
                    f"({r['reference_days']} days)" if r["reference_days"] else "–")
        cells = [r["pair"], str(r["days"]), f"{r['base']:.0f}", f"{r['candidate']:.0f}",
                 f"{r['difference']:+.0f} [{r['ci_low']:+.0f}, {r['ci_high']:+.0f}]",
                 f"{r['stranded_air_base']:.2f} / {r['stranded_ground_base']:.2f} → "
                 f"{r['stranded_air_candidate']:.2f} / {r['stranded_ground_candidate']:.2f}",
                 unforced, f"{r['collisions_base']:.2f} → {r['collisions_candidate']:.2f}",
                 *(_case_cell(r, c) for c in cases)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _case_cell(row: dict[str, Any], case: str) -> str:
    """The mean paired difference of one case and its 95 % CI, or nothing."""
    if case not in row["by_case"]:
        return ""
    low, high = row["by_case_ci"][case]
    return f"{row['by_case'][case]:+.0f} [{low:+.0f}, {high:+.0f}]"


def csv_text(rows: list[dict[str, Any]]) -> str:
    import io

    cases = sorted({c for r in rows for c in r["by_case"]})
    keys = [k for k in rows[0] if k not in ("by_case", "by_case_ci")]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(keys + [f"{col}_{c}" for c in cases
                            for col in ("difference", "ci_low", "ci_high")])
    for r in rows:
        per_case = []
        for c in cases:
            ci = r["by_case_ci"].get(c, ("", ""))
            per_case += [r["by_case"].get(c, ""), ci[0], ci[1]]
        writer.writerow([r[k] for k in keys] + per_case)
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m agents.evaluate.paired", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("episodes", nargs="+", help="episodes.csv files of agents.evaluate")
    parser.add_argument("--pair", nargs=2, action="append", required=True,
                        metavar=("BASE", "CANDIDATE"), help="agents to compare, as named in the "
                        "files (or by their names before 0.2.0); repeat for several pairs (a "
                        "pooled row is added)")
    parser.add_argument("--reference", nargs="+", metavar="AGENT",
                        help="the reference set of unforced losses (default: those of "
                             f"{', '.join(DEFAULT_REFERENCE)} the files hold)")
    parser.add_argument("--csv", help="also write the table here")
    args = parser.parse_args(argv)
    try:
        episodes = read_episodes(args.episodes)
        reference = (list(canonical_agents(args.reference)) if args.reference is not None
                     else [a for a in DEFAULT_REFERENCE if a in episodes])
        rows = compare(episodes, [canonical_agents(p) for p in args.pair], reference)
    except PairedInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(markdown(rows, reference), end="")
    if args.csv:
        write_atomic(Path(args.csv), csv_text(rows).encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
