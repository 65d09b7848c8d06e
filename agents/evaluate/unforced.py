"""Unforced losses in the evaluation's own summary.

On each day ``(case, seed)``, an agent's *unforced* losses are the vehicles it lost beyond the
fewest that any agent of a reference set lost on the same day
(:func:`unforced_losses`); a loss every reference agent also suffers is
forced by the day. The reference set is the dispatcher, the look-ahead planner and the
look-ahead guard (:data:`DEFAULT_REFERENCE`), those of them the
evaluation plays.

The number needs other agents' days, so it is made once every day is played: a row per agent and
case in the summary (``summary.csv``, ``results.json``, the console table, the report), right
after the vehicles lost, and never a column of the per-episode rows (``episodes.csv`` replays
day by day). An agent and case with no day a reference agent played have no row (the tables say
n/a).
"""

from __future__ import annotations

from typing import Any, Sequence

from agents.evaluate.metrics import DERIVED_AFTER, UNFORCED
from agents.evaluate.settings import EpisodeRecord, EvalSettings
from agents.evaluate.stats import describe

Day = tuple[str, int]  # (case, seed)
#: The reference set of unforced losses when ``--reference`` is not given: those of these
#: agents the files hold (the dispatcher, the look-ahead planner and the look-ahead guard).
DEFAULT_REFERENCE = ("dispatcher", "planner", "guard")


def unforced_losses(episodes: dict[str, dict[Day, dict[str, float]]], agent: str, day: Day,
                    reference: Sequence[str]) -> float | None:
    """``agent``'s *unforced* losses on ``day``: the vehicles it lost beyond the fewest any
    agent of ``reference`` lost on that day, ``max(0, lost(agent) - min_r lost(r))``; ``None``
    when no reference agent played the day. A loss every reference agent also suffers is
    forced by the day (its traffic, its failures), not by the controller."""
    best = [_lost(episodes[r][day]) for r in reference if day in episodes.get(r, {})]
    if not best:
        return None
    return max(0.0, _lost(episodes[agent][day]) - min(best))


def _lost(values: dict[str, float]) -> float:
    return values["stranded_air"] + values["stranded_ground"]


def reference_agents(settings: EvalSettings) -> list[str]:
    """The reference set of the unforced losses: those of the dispatcher, the look-ahead planner
    and the look-ahead guard that ``settings`` plays, in that order (empty: no unforced
    losses)."""
    return [a for a in DEFAULT_REFERENCE if a in settings.agents]


def unforced_rows(records: Sequence[EpisodeRecord], settings: EvalSettings,
                  reference: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """One summary row (metric :data:`~agents.evaluate.metrics.UNFORCED`) per agent and case:
    the mean, std, bootstrap CI and number ``n`` of its unforced losses over the days a reference
    agent played, in the order the agent played them. ``reference`` defaults to
    :func:`reference_agents`; agents and cases with no such day are left out."""
    reference = reference_agents(settings) if reference is None else list(reference)
    if not reference:
        return []
    lost: dict[str, dict[Day, dict[str, float]]] = {}
    for r in records:
        if r.metrics:
            lost.setdefault(r.task.agent, {})[(r.task.config, r.task.seed)] = {
                "stranded_air": float(r.metrics["stranded_air"]),
                "stranded_ground": float(r.metrics["stranded_ground"])}
    rows = []
    for agent in settings.agents:
        for config in settings.configs:
            days = [(r.task.config, r.task.seed) for r in records
                    if (r.task.agent, r.task.config) == (agent, config) and r.metrics]
            values = [u for u in (unforced_losses(lost, agent, d, reference) for d in days)
                      if u is not None]
            if values:
                stats = describe(values, settings.bootstrap, settings.confidence,
                                 settings.bootstrap_seed)
                rows.append({"agent": agent, "config": config, "metric": UNFORCED, **stats})
    return rows


def with_unforced(summary: Sequence[dict[str, Any]], rows: Sequence[dict[str, Any]]
                  ) -> list[dict[str, Any]]:
    """``summary`` with each agent and case's row of ``rows`` right after its
    :data:`~agents.evaluate.metrics.DERIVED_AFTER` row (the vehicles lost); a row with no such
    row to follow goes last."""
    pending = {(r["agent"], r["config"]): r for r in rows}
    out = []
    for row in summary:
        out.append(row)
        if row["metric"] == DERIVED_AFTER:
            extra = pending.pop((row["agent"], row["config"]), None)
            if extra is not None:
                out.append(extra)
    return out + list(pending.values())
