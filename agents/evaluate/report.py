"""The Markdown report and writing every output file of an evaluation."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any


from agents.common.provenance import describe
from agents.common.files import write_atomic
from agents.evaluate.metrics import (
    DIRECTION, HIDDEN_METRICS, METRIC_LABELS, VEHICLES_LOST, agent_label, case_label,
)
from agents.evaluate.settings import ACTION_EPISODES, Evaluation
from agents.evaluate.worst import worst_days
from agents.evaluate.tables import (
    CSV_DIGITS,
    decimals, episodes_csv, format_cell, format_interval, results_json, summary_csv,
    summary_metrics,
)
from agents.evaluate.figures import action_distribution_figure, case_study_figure
from agents.evaluate.interchange import marl_eval_json

# ============================================================================ report


METRIC_MEANINGS = """\
**What the metrics mean.** Every number is per simulated day (one episode of {steps}
steps) and is averaged over the evaluation days.
*Total reward* is the sum over the day's steps of the reward of the eVTOL acting at that step
(the paper's weighted sum of take-off, landing, battery, delay and safety terms).
*Mean battery* is the fleet's mean state of charge (%), averaged over the steps.
*Good take-offs* / *good landings* count take-offs and landing clearances that earned the
positive take-off / landing term (on time and with enough charge); *take-offs* and *landings*
count all of them, *failed take-offs* those lost to the uncertainty of case 2.
*Mean delay* is the lateness (minutes) of operations done more than the tolerance late, plus
those still pending at the end, summed per eVTOL and averaged over the fleet.
*Unresolved conflicts* are what the paper calls collisions (the column `collisions` of the
files): steps in which a conflict was predicted for the acting eVTOL and it was not told to
avoid it (safety term S = -5). They are predictions of the paper's conflict probe, not
collisions: no vehicle touched another. *Avoided conflicts* are steps with S = +5.
*Separation losses* (two eVTOLs closer than the minimum separation during a step) and
*contacts* (two bodies touching) are measured by the physics engine and do not enter the
reward. *Vehicles lost* (`vehicles_lost`, also `stranded` in the files) adds up the two ways
to lose one: *lost in the air* counts eVTOLs whose battery ran out in flight (an emergency
landing; out of service for the rest of the day; the paper's battery depletions, also
`battery_depletions` in the files); *lost on the ground* counts eVTOLs left on a normal port
with a battery from which no flight the ATC may clear reaches a charger (they never serve
again that day); *service lost* adds up the minutes from
each loss to the end of the day. *Unforced losses/day* are, on each day, the vehicles an agent
lost beyond the fewest that any reference agent (`dispatcher`, `planner` and `guard`, those
of them evaluated) lost on the same day, averaged over the days a
reference agent played (n/a where none did); a loss every reference agent suffers too is forced
by the day. *Landings below reserve* count completed trips that touched down with less battery
than the config's landing reserve (`battery.landing_reserve_pct`; 0 unless the config sets one,
as the realistic energy profile does, docs/energy.md); the emergency landings of depleted
vehicles are the depletions, not counted here. *Completed trips* are touchdowns after a landing
clearance.
"""


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return a["ci_low"] <= b["ci_high"] and b["ci_low"] <= a["ci_high"]


def _ranking_findings(evaluation: Evaluation, config: str) -> list[str]:
    """One generated sentence per directional metric: which agent's mean is best, and whether
    its CI separates it from the runner-up."""
    agents = [a for a in evaluation.settings.agents
              if evaluation.stat(a, config, "total_reward") is not None]
    if len(agents) < 2:
        return []
    out = []
    for metric, sign in DIRECTION.items():
        if metric not in evaluation.metrics:
            continue
        # A metric undefined for some agent's days (NaN: a separation with a fleet of one) is
        # not ranked: there is nothing to compare.
        rows = [evaluation.stat(a, config, metric) for a in agents]
        if any(r is None or not math.isfinite(r["mean"]) for r in rows):
            continue
        rows.sort(key=lambda r: -sign * r["mean"])
        best, second = rows[0], rows[1]
        word = "highest" if sign > 0 else "lowest"
        label = METRIC_LABELS.get(metric, metric)
        if best["mean"] == second["mean"]:
            tied = [agent_label(r["agent"]) for r in rows if r["mean"] == best["mean"]]
            d = decimals((best["ci_high"] - best["ci_low"]) / 2.0, best["mean"])
            out.append(f"{label}: {', '.join(tied)} have the same mean, {best['mean']:.{d}f}.")
            continue
        verdict = ("the 95 % CIs overlap, so these episodes do not separate the two"
                   if _overlap(best, second) else "the 95 % CIs do not overlap")
        out.append(f"{label}: {word} mean for {agent_label(best['agent'])} "
                   f"({format_interval(best)}), next {agent_label(second['agent'])} "
                   f"({format_interval(second)}); {verdict}.")
    return out


def _case_change_findings(evaluation: Evaluation) -> list[str]:
    """Per agent: how the means move from the first case to each other case."""
    s = evaluation.settings
    if len(s.configs) < 2:
        return []
    base, out = s.configs[0], []
    for other in s.configs[1:]:
        for agent in s.agents:
            parts = []
            for metric in ("total_reward", "good_takeoffs", "good_landings", "mean_delay_min",
                           "collisions", VEHICLES_LOST):
                a, b = (evaluation.stat(agent, base, metric), evaluation.stat(agent, other, metric))
                if a is None or b is None:
                    continue
                d = decimals((a["ci_high"] - a["ci_low"]) / 2, a["mean"])
                tag = "CIs overlap" if _overlap(a, b) else "CIs do not overlap"
                parts.append(f"{METRIC_LABELS[metric]} {a['mean']:.{d}f} → {b['mean']:.{d}f} "
                             f"({tag})")
            if parts:
                out.append(f"{agent_label(agent)}, {base} → {other}: " + "; ".join(parts) + ".")
    return out


def _report_table(evaluation: Evaluation, config: str) -> str:
    agents = [a for a in evaluation.settings.agents
              if evaluation.stat(a, config, evaluation.metrics[0]) is not None]
    metrics = [m for m in summary_metrics(evaluation) if m not in HIDDEN_METRICS]
    lines = ["| metric | " + " | ".join(agent_label(a) for a in agents) + " |",
             "|---|" + "---:|" * len(agents)]
    for metric in metrics:
        cells = [format_cell(evaluation.stat(a, config, metric)) for a in agents]
        lines.append(f"| {METRIC_LABELS.get(metric, metric)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _worst_days_text(evaluation: Evaluation) -> str:
    """The day each controller should be watched on, per case (:mod:`agents.evaluate.worst`),
    and the command that replays them rendered with their decision logs."""
    days = worst_days([{"agent": r.task.agent, "config": r.task.config,
                        "episode": r.task.episode, "seed": r.task.seed, "metrics": r.metrics}
                       for r in evaluation.records])
    rows = ["| agent | case | day (seed) | why | reward | vehicles lost | contacts |",
            "|---|---|---:|---|---:|---:|---:|"]
    rows += [f"| {w.agent} | {case_label(w.config)} | {w.seed} | {w.reason} | "
             f"{w.total_reward:.1f} | {w.vehicles_lost} | {w.contacts} |" for w in days]
    return ("Each controller's first day with a vehicle lost or a contact in each case, else its "
            "day of lowest reward:\n\n" + "\n".join(rows) + "\n\n"
            "`python -m agents.render.worst_day OUT` (OUT: the folder of this run's "
            "`results.json`) replays each of them and renders it around its first loss or "
            "contact (else its two hours of lowest reward) with the decision log of every turn, "
            "into `OUT/worst_day/`; `make evaluate` does it.")


def report_markdown(evaluation: Evaluation, command: str, report_path: Path,
                    figures: dict[str, Path]) -> str:
    """The Markdown report: provenance, one table per case, the figures, generated findings."""
    s = evaluation.settings
    seeds = s.seeds
    n = s.episodes
    pct = round(100 * s.confidence)
    steps = evaluation.stat(s.agents[0], s.configs[0], "steps")
    parts = ["# Evaluation results", "",
             f"Produced by `{command}`; made with {describe(evaluation.provenance)} "
             "(`provenance` in `results.json`).", "",
             f"Every agent played the same {n} evaluation day{'s' if n != 1 else ''} of each case "
             f"(seeds {seeds[0]} … {seeds[-1]}, `{s.seeds_rule}`; `agents/common/seeds.py` keeps "
             "them apart from every training seed), "
             "through the PettingZoo AEC API, with a fresh controller per day. "
             f"Cells are `mean [{pct} % CI]`, the CI being a percentile bootstrap of the mean "
             f"({s.bootstrap} resamples, generator seed {s.bootstrap_seed}). Per-episode numbers "
             f"are in `episodes.csv` (floats to {CSV_DIGITS} significant digits), the summary in "
             "`summary.csv`, and the record (settings, provenance, the summary at full "
             "precision, each day's action counts) in `results.json`, next to the figures."]
    if s.overrides:
        parts += ["", "Config overrides: " + ", ".join(f"`{k}={v!r}`" for k, v in s.overrides)
                  + "."]
    for config in s.configs:
        parts += ["", f"## {case_label(config)}", "", _report_table(evaluation, config)]
        findings = _ranking_findings(evaluation, config)
        if findings:
            parts += ["", "What these numbers show:", ""] + [f"- {f}" for f in findings]
    parts += ["", "## Figures", ""]
    for title, key in (("Case study", "case_study"),
                       ("Action distribution", "action_distribution")):
        rel = Path(os.path.relpath(figures[key], report_path.parent)).as_posix()
        parts.append(f"![{title}]({rel})")
        parts.append("")
    used = min(ACTION_EPISODES, n)
    parts.append(f"The case-study chart shows the mean per day with {pct} % CI error bars; the "
                 f"action-distribution chart the share of each action executed by the acting "
                 f"eVTOL over the first {used} evaluation day{'s' if used != 1 else ''}.")
    changes = _case_change_findings(evaluation)
    if changes:
        parts += ["", "## From one case to the other", ""] + [f"- {c}" for c in changes]
    parts += ["", "## Worst days", "", _worst_days_text(evaluation)]
    parts += ["", "## Metrics", "",
              METRIC_MEANINGS.format(steps=f"{steps['mean']:g}" if steps else "?").strip()]
    return "\n".join(parts) + "\n"


# ============================================================================ writing it all


def write_outputs(evaluation: Evaluation, out: Path, command: str,
                  report: Path | None = None) -> list[Path]:
    """Write the files of ``evaluation`` into ``out`` (each atomically); ``results.json`` last.

    An incomplete run writes only ``episodes.csv``, ``summary.csv`` and ``results.json``
    (with ``"complete": false`` and the error). Returns the paths written.
    """
    out.mkdir(parents=True, exist_ok=True)
    written = []

    def put(name: str | Path, data: bytes | str) -> None:
        path = out / name if isinstance(name, str) else name
        write_atomic(path, data)
        written.append(path)

    put("episodes.csv", episodes_csv(evaluation))
    put("summary.csv", summary_csv(evaluation))
    if evaluation.complete:
        put("marl_eval.json", marl_eval_json(evaluation))
        figures = {"case_study": out / "case_study.png",
                   "action_distribution": out / "action_distribution.png"}
        put(figures["case_study"], case_study_figure(evaluation))
        put(figures["action_distribution"], action_distribution_figure(evaluation))
        if report is not None:
            put(report, report_markdown(evaluation, command, report, figures))
    put("results.json", results_json(evaluation, command))
    return written


