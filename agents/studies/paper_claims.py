"""The paper's case-study claims beside this project's measurements (``marl-vertiport
paper-claims``).

The paper's case-study figure is not in its text; its claims are (section "Case studies" and
the conclusion). Each claim is written here as a comparison this project can measure on the
same controllers: the paper's random and FCFS baselines and its graph-learning agent (GRL,
here the shipped GCN policy alone, ``gcn``), in case 1 (``paper``) and case 2
(``paper_uncertain``), and beside them the dispatcher, the project's bar. Every comparison is
paired on the days both sides played (same case and seed, or the same seed in the two cases)
with a 95 % percentile-bootstrap interval of the mean difference, and marked:

* **reproduced**: the interval lies on the side the paper claims;
* **reversed**: it lies on the other side;
* **not separated**: it holds 0, so these days cannot tell.

A claim about a size (the battery drops by about 13 %) also gives the measured size. The input
is an ``episodes.csv`` of ``marl-vertiport evaluate`` that holds those agents in both cases
(by default the shipped results, ``docs/results/episodes.csv``: 200 test days a case)::

    marl-vertiport paper-claims                                   # prints the Markdown table
    marl-vertiport paper-claims --out docs/results/paper_claims.md
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from agents.common.files import write_atomic
from agents.common.names import canonical_spec
from agents.common.provenance import REPO_ROOT
from agents.evaluate.stats import bootstrap_ci

PROG = "python -m agents.studies.paper_claims"
#: The shipped results the claims are measured on by default.
DEFAULT_EPISODES = REPO_ROOT / "docs" / "results" / "episodes.csv"
CASE_1, CASE_2 = "paper", "paper_uncertain"
#: The metrics the claims read, and how the table names them.
LABELS = {"total_reward": "total reward", "collisions": "unresolved conflicts (the paper's "
          "collisions)", "mean_battery_pct": "mean battery (%)", "mean_delay_min":
          "mean delay (min)", "good_takeoffs": "good take-offs", "good_landings": "good landings"}


@dataclass(frozen=True)
class Claim:
    """One claim of the paper: ``left`` against ``right`` (``agent@case``) on ``metric``, said
    to be higher (``sign`` +1) or lower (-1); ``size_pct``: a relative size the paper gives."""

    where: str
    text: str
    metric: str
    left: str
    right: str
    sign: int
    size_pct: float | None = None


#: The paper's claims, in its words where it gives them. GRL is ``gcn``.
CLAIMS = (
    Claim("case 1", "GRL ahead of FCFS on total reward", "total_reward",
          f"gcn@{CASE_1}", f"fcfs@{CASE_1}", +1),
    Claim("case 1", "GRL ahead of random on total reward", "total_reward",
          f"gcn@{CASE_1}", f"random@{CASE_1}", +1),
    Claim("case 1", "FCFS second, random worst, on total reward", "total_reward",
          f"fcfs@{CASE_1}", f"random@{CASE_1}", +1),
    Claim("case 1", "GRL worse than FCFS on collisions", "collisions",
          f"gcn@{CASE_1}", f"fcfs@{CASE_1}", +1),
    Claim("case 2", "GRL ahead of FCFS on total reward", "total_reward",
          f"gcn@{CASE_2}", f"fcfs@{CASE_2}", +1),
    Claim("case 2", "GRL ahead of random on total reward", "total_reward",
          f"gcn@{CASE_2}", f"random@{CASE_2}", +1),
    Claim("case 2", "GRL worse than FCFS on collisions", "collisions",
          f"gcn@{CASE_2}", f"fcfs@{CASE_2}", +1),
    Claim("case 1 → 2", "GRL's reward drops", "total_reward",
          f"gcn@{CASE_2}", f"gcn@{CASE_1}", -1),
    Claim("case 1 → 2", "GRL's battery drops by about 13 %", "mean_battery_pct",
          f"gcn@{CASE_2}", f"gcn@{CASE_1}", -1, size_pct=-13.0),
    Claim("case 1 → 2", "GRL's delay rises", "mean_delay_min",
          f"gcn@{CASE_2}", f"gcn@{CASE_1}", +1),
    Claim("case 1 → 2", "GRL's good take-offs fall", "good_takeoffs",
          f"gcn@{CASE_2}", f"gcn@{CASE_1}", -1),
    Claim("case 1 → 2", "GRL's good landings fall", "good_landings",
          f"gcn@{CASE_2}", f"gcn@{CASE_1}", -1),
    Claim("case 1 → 2", "GRL's collisions fall a little", "collisions",
          f"gcn@{CASE_2}", f"gcn@{CASE_1}", -1),
    Claim("case 1 → 2", "FCFS's reward drops", "total_reward",
          f"fcfs@{CASE_2}", f"fcfs@{CASE_1}", -1),
    Claim("case 1 → 2", "FCFS's delay falls", "mean_delay_min",
          f"fcfs@{CASE_2}", f"fcfs@{CASE_1}", -1),
)
#: The bar beside the paper's controllers: the same comparisons with the dispatcher where GRL is.
BAR = "dispatcher"


class ClaimsError(ValueError):
    """An input that cannot measure the claims (the message names what is missing)."""


def read_days(path: Path) -> dict[str, dict[int, dict[str, float]]]:
    """``agent@case`` -> seed -> the metrics the claims read, from an ``episodes.csv`` (agents
    named before 0.2.0 under their names now)."""
    out: dict[str, dict[int, dict[str, float]]] = {}
    try:
        with path.open(newline="") as fh:
            for row in csv.DictReader(fh):
                key = f"{canonical_spec(row['agent'], note=False)}@{row['config']}"
                out.setdefault(key, {})[int(row["seed"])] = {m: float(row[m]) for m in LABELS}
    except (OSError, KeyError, ValueError) as exc:
        raise ClaimsError(f"{path}: not an evaluation's episodes.csv with the metrics "
                          f"{', '.join(LABELS)} ({exc})") from None
    return out


def measure(claim: Claim, days: dict[str, dict[int, dict[str, float]]],
            grl: str = "gcn") -> dict[str, object]:
    """The claim's paired difference (left minus right) on the seeds both sides played, its
    interval, the relative change where the claim gives a size, and the verdict; ``grl`` plays
    the paper's GRL (``dispatcher`` for the bar's column)."""
    left, right = (side.replace("gcn@", f"{grl}@") for side in (claim.left, claim.right))
    for side in (left, right):
        if side not in days:
            raise ClaimsError(f"the episodes hold no days of {side.replace('@', ' on ')}")
    seeds = sorted(set(days[left]) & set(days[right]))
    if not seeds:
        raise ClaimsError(f"{left} and {right} played no day in common")
    a = np.array([days[left][s][claim.metric] for s in seeds])
    b = np.array([days[right][s][claim.metric] for s in seeds])
    diff = a - b
    low, high = bootstrap_ci(diff)
    if low > 0 or high < 0:
        verdict = "reproduced" if (low > 0) == (claim.sign > 0) else "reversed"
    else:
        verdict = "not separated"
    size = 100.0 * float(diff.mean()) / float(b.mean()) if b.mean() else math.nan
    return {"left": float(a.mean()), "right": float(b.mean()), "difference": float(diff.mean()),
            "ci": (low, high), "days": len(seeds), "size_pct": size, "verdict": verdict}


def _cell(m: dict[str, object], claim: Claim) -> str:
    low, high = m["ci"]
    text = (f"{m['left']:.1f} vs {m['right']:.1f}: {m['difference']:+.1f} "
            f"[{low:+.1f}, {high:+.1f}], **{m['verdict']}**")
    if claim.size_pct is not None:
        text += f"; {m['size_pct']:+.1f} % (the paper: about {claim.size_pct:+.0f} %)"
    return text


def table(days: dict[str, dict[int, dict[str, float]]], source: str) -> str:
    """The Markdown page: each claim, this project's GRL (``gcn``) and, beside it, the
    dispatcher in GRL's place."""
    n = len(next(iter(days.values())))
    lines = [
        "# The paper's case-study claims, measured here", "",
        f"Made by `marl-vertiport paper-claims` from `{source}` ({n} days per agent and case; "
        "paired on the same seeds). GRL is the shipped policy alone (`gcn`); the last column "
        "puts the dispatcher, the project's bar, in GRL's place. Each cell: the two means, their "
        "paired difference with its 95 % interval, and the verdict: reproduced (the interval "
        "on the paper's side of 0), reversed, or not separated (it holds 0).", "",
        "| where | the paper's claim | metric | GRL (`gcn`) | the dispatcher in GRL's place |",
        "|---|---|---|---|---|"]
    for claim in CLAIMS:
        grl = measure(claim, days)
        bar = measure(claim, days, BAR) if "gcn" in claim.left + claim.right else None
        lines.append(f"| {claim.where} | {claim.text} | {LABELS[claim.metric]} | "
                     f"{_cell(grl, claim)} | {_cell(bar, claim) if bar else '(no GRL in the claim)'} |")
    verdicts = [measure(c, days)["verdict"] for c in CLAIMS]
    lines += ["", f"{verdicts.count('reproduced')} of {len(CLAIMS)} claims reproduced, "
              f"{verdicts.count('reversed')} reversed, {verdicts.count('not separated')} not "
              "separated."]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=Path, default=DEFAULT_EPISODES,
                        help="an episodes.csv with random, fcfs, gcn and the dispatcher in "
                             "paper and paper_uncertain (default: the shipped results)")
    parser.add_argument("--out", type=Path, help="also write the Markdown page here")
    args = parser.parse_args(argv)
    try:
        days = read_days(args.episodes)
        try:
            source = args.episodes.resolve().relative_to(REPO_ROOT).as_posix()
        except ValueError:
            source = str(args.episodes)
        text = table(days, source)
    except ClaimsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(text, end="")
    if args.out:
        write_atomic(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
