"""How the evaluation shows the metrics: which appear in the table and the figures, their
labels and directions (from the simulator's registry, :mod:`marl_vertiport.sim.metrics`), and
the cases' display names."""

from __future__ import annotations

from marl_vertiport.sim.metrics import METRICS, MetricInfo

#: The unforced losses a day (:mod:`agents.evaluate.unforced`): derived across agents once
#: every day is played, so a row of the summary but never a column of the per-episode files.
UNFORCED = "unforced_losses"
#: The summary's metrics derived across agents, each shown right after the metric it follows.
DERIVED_METRICS: dict[str, MetricInfo] = {UNFORCED: MetricInfo("unforced losses/day", better=-1)}
#: The episode metric the derived metrics follow in the summary, tables and report.
DERIVED_AFTER = "stranded"
#: Metric -> short label with its unit, for tables and figures (from the simulator's registry).
METRIC_LABELS = {name: info.label for name, info in {**METRICS, **DERIVED_METRICS}.items()}
#: Columns of the printed table (agents as rows).
TABLE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                 "mean_delay_min", "collisions", "separation_losses", "min_separation_m",
                 "separation_loss_min", "trail_hold_min", "contacts", "stranded_air",
                 "stranded_ground", UNFORCED, "reserve_violations", "service_min_lost")
#: Panels of the case-study chart.
FIGURE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                  "mean_delay_min", "collisions", "separation_losses", "min_separation_m",
                  "contacts", "stranded_air", "stranded_ground")
#: Which way is better for an episode metric (+1 higher, -1 lower), for the report's generated
#: findings.
DIRECTION = {name: info.better for name, info in METRICS.items() if info.better}
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
    info = METRICS.get(metric)
    return info.axis if info is not None else metric
