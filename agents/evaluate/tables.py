"""Text and data outputs: the console table, and the CSV and JSON files."""

from __future__ import annotations

import csv
import io
import json
import math
from typing import Any, Iterable, Sequence


from agents.evaluate.metrics import (
    DERIVED_AFTER, DERIVED_METRICS, METRIC_LABELS, TABLE_METRICS, agent_label, case_label,
)
from agents.evaluate.settings import Evaluation
from agents.evaluate.unforced import reference_agents


def decimals(half_width: float, mean: float) -> int:
    scale = half_width if half_width > 0 else abs(mean)
    if not math.isfinite(scale) or scale < 1:
        return 2
    return 1 if scale < 10 else 0


def format_interval(row: dict[str, Any]) -> str:
    """``mean [ci_low, ci_high]``: the percentile bootstrap's interval, which need not be
    symmetric; ``mean [n/a]`` for a single episode, which has no interval."""
    half = (row["ci_high"] - row["ci_low"]) / 2.0
    d = decimals(half, row["mean"])
    if row["n"] < 2:
        return f"{row['mean']:.{d}f} [n/a]"
    return f"{row['mean']:.{d}f} [{row['ci_low']:.{d}f}, {row['ci_high']:.{d}f}]"


def summary_metrics(evaluation: Evaluation) -> list[str]:
    """The metrics of the summary in the order the tables show them: the episode metrics, with
    those derived across agents (the unforced losses) right after the vehicles lost, where the
    summary has them."""
    present = {row["metric"] for row in evaluation.summary}
    derived = [m for m in DERIVED_METRICS if m in present]
    out: list[str] = []
    for metric in evaluation.metrics:
        out.append(metric)
        if metric == DERIVED_AFTER:
            out += derived
    return out + [m for m in derived if m not in out]


def format_cell(row: dict[str, Any] | None) -> str:
    """:func:`format_interval`, or ``n/a`` for a metric an agent has no value of in a case (no
    unforced losses where no reference agent played its days)."""
    return "n/a" if row is None else format_interval(row)


#: The console table's width at most, in characters.
TABLE_WIDTH = 120
#: Short headers of the console table's columns.
TABLE_HEADERS = {"total_reward": "total reward", "vehicles_lost": "lost", "unforced_losses":
                 "unforced", "contacts": "contacts", "separation_losses": "sep. losses",
                 "collisions": "unres. conflicts", "mean_delay_min": "delay (min)"}


def _short(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters, its middle replaced by ``~`` where it is longer."""
    if len(text) <= width:
        return text
    keep = width - 1
    return text[:keep // 2] + "~" + text[len(text) - (keep - keep // 2):]


def _mean_cell(row: dict[str, Any] | None) -> str:
    if row is None:
        return "n/a"
    d = decimals((row["ci_high"] - row["ci_low"]) / 2.0, row["mean"])
    return f"{row['mean']:.{d}f}"


def format_table(evaluation: Evaluation) -> str:
    """The console table, at most :data:`TABLE_WIDTH` characters wide: one block per case,
    agents as rows, the reward as ``mean [95 % CI]`` and the safety counts a day as means
    (every metric with its interval is in ``summary.csv`` and the report)."""
    shown = summary_metrics(evaluation)
    metrics = [m for m in TABLE_METRICS if m in shown]
    pct = round(100 * evaluation.settings.confidence)
    blocks = []
    for config in evaluation.settings.configs:
        agents = [a for a in evaluation.settings.agents
                  if metrics and evaluation.stat(a, config, metrics[0]) is not None]
        if not agents:
            continue
        cells = [[format_cell(evaluation.stat(a, config, m)) if m == "total_reward"
                  else _mean_cell(evaluation.stat(a, config, m)) for m in metrics]
                 for a in agents]
        header = [TABLE_HEADERS.get(m, m) for m in metrics]
        widths = [max(len(line[i]) for line in [header, *cells]) for i in range(len(metrics))]
        room = TABLE_WIDTH - sum(w + 2 for w in widths)
        names = [_short(agent_label(a), max(12, room)) for a in agents]
        first = max(len("agent"), *(len(n) for n in names))
        n = max(evaluation.stat(a, config, metrics[0])["n"] for a in agents)
        lines = [f"{case_label(config)}: {n} day{'s' if n != 1 else ''}; reward mean [{pct} % "
                 f"bootstrap CI], the rest means a day"
                 + (" (one episode: no interval)" if n == 1 else ""),
                 "  ".join(["agent".ljust(first), *(h.rjust(w) for h, w in zip(header, widths))]),
                 "  ".join("-" * w for w in [first, *widths])]
        lines += ["  ".join([name.ljust(first), *(c.rjust(w) for c, w in zip(row, widths))])
                  for name, row in zip(names, cells)]
        blocks.append("\n".join(line[:TABLE_WIDTH] for line in lines))
    note = ("lost: vehicles lost in the air and on the ground; unforced: lost beyond the fewest "
            "any reference agent lost that day\nunres. conflicts: predicted conflicts left "
            "unresolved (the paper's collisions, S = -5), not contacts\nevery metric, with its "
            "interval: summary.csv and the report")
    return "\n\n".join(blocks + [note]) if blocks else ""


# ============================================================================ files


def csv_text(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """CSV with a header line and ``\\n`` line ends."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


#: Significant digits of a float metric in the per-episode files (``episodes.csv``,
#: ``sweep.csv``). The last bits of a day's float sums (its reward, its mean battery) differ
#: between CPUs (by about 1e-13 between two 2-core AMD EPYC machines of this project), while
#: the counts and every decision agree; ten digits keep far more than any result needs and
#: make the files, and the replay of ``make check-results``, the same on both.
CSV_DIGITS = 10


def csv_metric(value: Any) -> Any:
    """A metric as the per-episode files write it: floats to :data:`CSV_DIGITS` significant
    digits, anything else as it is."""
    if isinstance(value, float):
        return f"{value:.{CSV_DIGITS}g}"
    return value


def episodes_csv(evaluation: Evaluation) -> str:
    """One row per completed episode: agent, config, episode, seed, every scalar metric
    (floats to :data:`CSV_DIGITS` significant digits)."""
    header = ["agent", "config", "episode", "seed", *evaluation.metrics]
    rows = ([r.task.agent, r.task.config, r.task.episode, r.task.seed,
             *(csv_metric(r.metrics[m]) for m in evaluation.metrics)] for r in evaluation.records)
    return csv_text(header, rows)


def summary_csv(evaluation: Evaluation) -> str:
    """One row per agent x case x metric: mean, std, ci_low, ci_high, n."""
    header = ["agent", "config", "metric", "mean", "std", "ci_low", "ci_high", "n"]
    return csv_text(header, ([row[k] for k in header] for row in evaluation.summary))


#: The lists of a result record written one entry per line (they have an entry per episode, or
#: per agent x case x metric: thousands in a shipped set).
ONE_LINE_ENTRIES = ("episodes", "summary")


def record_json(doc: dict[str, Any]) -> str:
    """``doc`` as JSON, the lists of :data:`ONE_LINE_ENTRIES` one entry per line and every
    other value indented: valid JSON, readable in a diff, and a line per episode."""
    parts = []
    for key, value in doc.items():
        if key in ONE_LINE_ENTRIES and isinstance(value, list) and value:
            entries = ",\n".join("  " + json.dumps(e, allow_nan=True) for e in value)
            parts.append(f" {json.dumps(key)}: [\n{entries}\n ]")
        else:
            text = json.dumps(value, indent=1, allow_nan=True).replace("\n", "\n ")
            parts.append(f" {json.dumps(key)}: {text}")
    return "{\n" + ",\n".join(parts) + "\n}\n"


def results_json(evaluation: Evaluation, command: str) -> str:
    """The record of an evaluation: settings, provenance, the summary (with the unforced
    losses, and the reference agents they were measured against), and per episode what
    ``episodes.csv`` does not hold (its action counts; the CSV has every scalar metric)."""
    scalar = set(evaluation.metrics)
    doc = {
        "complete": evaluation.complete,
        "error": evaluation.error,
        "command": command,
        "provenance": evaluation.provenance,
        "settings": evaluation.settings.to_json(),
        "action_names": evaluation.action_names,
        "metrics": evaluation.metrics,
        "episodes": [{"agent": r.task.agent, "config": r.task.config, "episode": r.task.episode,
                      "seed": r.task.seed,
                      "metrics": {k: v for k, v in r.metrics.items() if k not in scalar}}
                     for r in evaluation.records],
        "summary": evaluation.summary,
        "unforced_reference": reference_agents(evaluation.settings),
    }
    return record_json(doc)


