"""The test-day table of experiments/prior-actor-proposes: for each policy, per case, its reward
a day and the paired difference with the dispatcher [95 % CI], vehicles lost and unforced
losses a day (beyond the dispatcher's on the same day), contacts, losses of separation, the
least separation, mean delay and completed trips; and all days together.

Run from the repository root (prints Markdown)::

    python experiments/prior-actor-proposes/test_table.py
    python experiments/prior-actor-proposes/test_table.py zero_shot.csv   # or noise.csv

With a file of this folder named, its own days are tabled (the dispatcher's rows among them).
"""

import sys
from pathlib import Path

import pandas as pd

from agents.evaluate.stats import bootstrap_ci
from agents.evaluate.unforced import unforced_losses

HERE = Path(__file__).parent
#: The dispatcher's test-day rows are rule-prior's (the same days, played the same way).
FILES = (HERE.parent / "rule-prior" / "test_days.csv", HERE / "test_days.csv")
CASES = {"paper": "case 1", "paper_uncertain": "case 2", "paper_uncertain_10": "10 %"}
BASE = "dispatcher"


def _gain(diff: pd.Series, mean_base: float) -> str:
    low, high = bootstrap_ci(diff.to_numpy())
    text = f"{diff.mean():+.0f} [{low:+.0f}, {high:+.0f}] ({100 * diff.mean() / mean_base:+.1f} %)"
    return text.replace("-", "\u2212")


def main() -> None:
    files = [HERE / sys.argv[1]] if len(sys.argv) > 1 else FILES
    days = pd.concat([pd.read_csv(f) for f in files])
    days["lost"] = days.stranded_air + days.stranded_ground
    agents = [BASE] + sorted(a for a in pd.read_csv(files[-1]).agent.unique() if a != BASE)
    by = {a: days[days.agent == a].set_index(["config", "seed"]).sort_index() for a in agents}
    base = by[BASE]
    episodes = {a: rows.to_dict("index") for a, rows in by.items()}  # {(case, seed): metrics}
    print("| controller | case | reward a day | − dispatcher [95 % CI] | lost a day | unforced a day "
          "| contacts | separation losses (least, m) | delay (min) | trips a day |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for agent in agents:
        rows = by[agent]
        cases = [c for c in CASES if c in rows.index] or list(rows.index.unique(0))
        for case in (*cases, "all") if len(cases) > 1 else cases:
            mine = rows if case == "all" else rows.loc[[case]]  # indexed by (case, seed)
            ref = base.loc[mine.index]
            gain = "" if agent == BASE else _gain(mine.total_reward - ref.total_reward,
                                                   ref.total_reward.mean())
            unforced = "" if agent == BASE else "{:.3f}".format(pd.Series(
                [unforced_losses(episodes, agent, day, [BASE]) for day in mine.index]).mean())
            print(f"| {agent} | {CASES.get(case, case)} ({len(mine)}) | {mine.total_reward.mean():.0f} "
                  f"| {gain} | {mine.lost.mean():.3f} | {unforced} | {int(mine.contacts.sum())} "
                  f"| {int(mine.separation_losses.sum())} ({mine.min_separation_m.min():.2f}) "
                  f"| {mine.mean_delay_min.mean():.0f} | {mine.completed_trips.mean():.1f} |")


if __name__ == "__main__":
    main()
