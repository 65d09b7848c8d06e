"""Which day of an evaluation an operator should watch first, per controller and case: its first
day with a vehicle lost or a contact, else its day of lowest reward (the worst-day replay,
``python -m agents.render.worst_day``, renders it with its decision log).

"First" is in the evaluation's order of days (its seeds, as played); a day's vehicles lost are
its ``stranded`` count (in the air and on the ground), its contacts the ``contacts`` count.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["WorstDay", "worst_days"]


@dataclass(frozen=True)
class WorstDay:
    """One controller's day to replay in one case, and why it was picked."""

    agent: str
    config: str
    seed: int
    episode: int
    reason: str
    """``"first loss or contact"`` or ``"lowest reward"``."""
    total_reward: float
    vehicles_lost: int
    contacts: int


def _metric(row: dict[str, Any], key: str) -> Any:
    return row["metrics"][key] if "metrics" in row else row[key]


def worst_days(episodes: list[dict[str, Any]]) -> list[WorstDay]:
    """Per (agent, config) of ``episodes`` (results.json's rows, ``agent``, ``config``,
    ``episode``, ``seed`` and ``metrics``; or episodes.csv's flat rows), in the order they first
    appear: the first day with a vehicle lost or a contact, else the lowest reward (the first
    of equal ones)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in episodes:
        groups.setdefault((str(row["agent"]), str(row["config"])), []).append(row)
    out = []
    for (agent, config), rows in groups.items():
        rows = sorted(rows, key=lambda r: int(r["episode"]))
        bad = [r for r in rows if int(_metric(r, "stranded")) > 0 or int(_metric(r, "contacts")) > 0]
        if bad:
            pick, reason = bad[0], "first loss or contact"
        else:
            pick = min(rows, key=lambda r: float(_metric(r, "total_reward")))
            reason = "lowest reward"
        out.append(WorstDay(agent, config, int(pick["seed"]), int(pick["episode"]), reason,
                            float(_metric(pick, "total_reward")), int(_metric(pick, "stranded")),
                            int(_metric(pick, "contacts"))))
    return out
