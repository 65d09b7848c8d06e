"""The evaluation's metrics: label with unit, which way is better, which appear in the
table and the figures, and the cases' display names; defined here once."""

from __future__ import annotations




#: Metric -> short label with its unit, for tables and figures.
METRIC_LABELS = {
    "steps": "steps",
    "total_reward": "total reward",
    "mean_battery_pct": "mean battery (%)",
    "good_takeoffs": "good take-offs",
    "good_landings": "good landings",
    "takeoffs": "take-offs",
    "failed_takeoffs": "failed take-offs",
    "landings": "landings",
    "mean_delay_min": "mean delay (min)",
    "collisions": "collisions",
    "avoided_conflicts": "avoided conflicts",
    "separation_losses": "separation losses",
    "contacts": "contacts",
    "battery_depletions": "depletions",
    "stranded_air": "lost in the air",
    "stranded_ground": "lost on the ground",
    "stranded": "vehicles lost",
    "service_min_lost": "service lost (min)",
    "completed_trips": "completed trips",
}
#: Columns of the printed table (agents as rows).
TABLE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                 "mean_delay_min", "collisions", "separation_losses", "stranded_air",
                 "stranded_ground", "service_min_lost")
#: Panels of the case-study chart.
FIGURE_METRICS = ("total_reward", "mean_battery_pct", "good_takeoffs", "good_landings",
                  "mean_delay_min", "collisions", "stranded_air", "stranded_ground")
#: Which way is better for a metric (+1 higher, -1 lower), for the report's generated findings.
DIRECTION = {"total_reward": 1, "mean_battery_pct": 1, "good_takeoffs": 1, "good_landings": 1,
             "mean_delay_min": -1, "collisions": -1, "separation_losses": -1,
             "battery_depletions": -1, "stranded_air": -1, "stranded_ground": -1,
             "stranded": -1, "service_min_lost": -1}
CASE_LABELS = {"paper": "case 1, no uncertainty", "paper_uncertain": "case 2, with uncertainty",
               "paper_uncertain_10": "case 2 with every uncertainty at 10 %"}



def case_label(config: str) -> str:
    """``paper`` -> ``paper (case 1, no uncertainty)``; other configs by name."""
    return f"{config} ({CASE_LABELS[config]})" if config in CASE_LABELS else config


def agent_label(spec: str) -> str:
    """Short display name: the class name of an import path, else the spec."""
    return spec.rsplit(":", 1)[-1] if ":" in spec else spec

