"""How the evaluation shows the metrics: which appear in the table and the figures, their
labels and directions (from the simulator's registry, :mod:`marl_vertiport.sim.metrics`), and
the cases' display names."""

from __future__ import annotations

from marl_vertiport.sim.metrics import METRICS, MetricInfo

#: The vehicles lost in a day, in the air and on the ground: the simulator's ``stranded``,
#: under the name the evaluation's tables, files and figures give it (a column of
#: ``episodes.csv`` beside ``stranded``, which stays for the files made before).
VEHICLES_LOST = "vehicles_lost"
#: Per-episode metrics the evaluation adds to the simulator's, and what each one repeats.
EPISODE_ALIASES = {VEHICLES_LOST: "stranded"}
#: The unforced losses a day (:mod:`agents.evaluate.unforced`): derived across agents once
#: every day is played, so a row of the summary but never a column of the per-episode files.
UNFORCED = "unforced_losses"
#: The summary's metrics derived across agents, each shown right after the metric it follows.
DERIVED_METRICS: dict[str, MetricInfo] = {UNFORCED: MetricInfo("unforced losses/day", better=-1)}
#: The episode metric the derived metrics follow in the summary, tables and report.
DERIVED_AFTER = VEHICLES_LOST
#: Every metric the evaluation shows: the simulator's, and those it adds.
SHOWN_METRICS: dict[str, MetricInfo] = {
    **METRICS, VEHICLES_LOST: MetricInfo("vehicles lost", better=-1), **DERIVED_METRICS}
#: Metrics kept in the files but left out of the tables, figures and findings: each repeats
#: another that is shown (``stranded`` is ``vehicles_lost``, ``battery_depletions`` the
#: vehicles lost in the air), so a reader meets one label per quantity.
HIDDEN_METRICS = ("steps", "stranded", "battery_depletions")
#: Metric -> short label with its unit, for tables and figures (from the simulator's registry).
METRIC_LABELS = {name: info.label for name, info in SHOWN_METRICS.items()}
#: Columns of the printed table (agents as rows): it fits 120 columns; every metric, with its
#: interval, is in summary.csv and the report.
TABLE_METRICS = ("total_reward", VEHICLES_LOST, UNFORCED, "contacts", "separation_losses",
                 "collisions", "mean_delay_min")
#: Panels of the case-study chart.
FIGURE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                  "mean_delay_min", "collisions", "separation_losses", "min_separation_m",
                  "contacts", "stranded_air", "stranded_ground", VEHICLES_LOST)
#: Which way is better for an episode metric (+1 higher, -1 lower), for the report's generated
#: findings.
DIRECTION = {name: info.better for name, info in SHOWN_METRICS.items()
             if info.better and name not in HIDDEN_METRICS and name not in DERIVED_METRICS}


def with_aliases(metrics: dict) -> dict:
    """A day's metrics with those of :data:`EPISODE_ALIASES` right after what they repeat."""
    out = {}
    for key, value in metrics.items():
        out[key] = value
        out.update({alias: value for alias, of in EPISODE_ALIASES.items() if of == key})
    return out
CASE_LABELS = {"paper": "case 1, no uncertainty", "paper_uncertain": "case 2, with uncertainty",
               "paper_uncertain_10": "case 2 with every uncertainty at 10 %"}


def case_label(config: str) -> str:
    """``paper`` -> ``paper (case 1, no uncertainty)``; other configs by name."""
    return f"{config} ({CASE_LABELS[config]})" if config in CASE_LABELS else config


def agent_label(spec: str) -> str:
    """Short display name: the class name of an import path, else the spec."""
    return spec.rsplit(":", 1)[-1] if ":" in spec else spec


def axis_label(metric: str) -> str:
    """The y-axis label of a metric's chart."""
    info = SHOWN_METRICS.get(metric)
    return info.axis if info is not None else metric
